//! `goby console` against a real Mosquitto broker on loopback and two
//! gateways — the fleet quick start's `gobyd/config/fleet-vehicle1.pb.txt`
//! and `fleet-vehicle2.pb.txt` (ports moved to free ones), each a gobyd
//! run in-process with its MQTT bridge — and, in the browser test, a
//! headless Chromium driven over the Chrome DevTools protocol: the map
//! shows both nodes from the reports they send, a command filled in the
//! commander's form and sent from it arrives at the other node, and its ack
//! shows in the page; a node's TDMA cycle shows and a MAC update sent from
//! the page's form changes it. Without a browser, each node's cycle and
//! MAC switcher, learned from the broker and from the JSON interface, and
//! MAC updates and switches sent through the console's interface. Screenshots, and the page's load time and update
//! latency, are kept under the target directory
//! (`CARGO_TARGET_TMPDIR/console/`). Fails without Mosquitto
//! (`.ci/mosquitto.sh`); the browser test is ignored without Chromium
//! (`.ci/chromium.sh`).

#[path = "../../gobyd/tests/support/broker.rs"]
mod broker;

#[path = "support/gobyd_child.rs"]
mod gobyd_child;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpStream, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use broker::{Broker, Seen, Watcher};
use serde_json::{json, Value};

/// Upper bound of a wait on the acoustic link: the quick start's TDMA
/// cycle is 16 s, a command and its ack take two or three of them (one
/// more for a lost packet).
const LINK_PATIENCE: Duration = Duration::from_secs(150);

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-console-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn now_ms() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
        * 1000.0
}

/// The quick start's two vehicles, on free ports, bridged to `broker`,
/// their data directories in `dir`: the configuration files written.
fn fleet_configs(dir: &Path, broker: &str) -> Vec<PathBuf> {
    let ports = [free_udp_port(), free_udp_port()];
    (1..=2)
        .map(|i| {
            let text = std::fs::read_to_string(
                repo().join(format!("gobyd/config/fleet-vehicle{i}.pb.txt")),
            )
            .unwrap();
            let text = text
                .replace("127.0.0.1:1883", broker)
                .replace("port: 50111", &format!("port: {}", ports[0]))
                .replace("port: 50112", &format!("port: {}", ports[1]))
                .replace(&format!("127.0.0.1:1115{i}"), "127.0.0.1:0")
                .replace(
                    &format!("\"fleet-vehicle{i}-data\""),
                    &format!("\"{}\"", dir.join(format!("vehicle{i}")).display()),
                );
            assert!(
                text.contains(broker) && text.contains("127.0.0.1:0\""),
                "{text}"
            );
            let path = dir.join(format!("fleet-vehicle{i}.pb.txt"));
            std::fs::write(&path, text).unwrap();
            path
        })
        .collect()
}

/// The gateways: each a gobyd process on its configuration (this test
/// binary run again as [`gateway_process`], which runs the `gobyd` library's
/// command line as the `gobyd` binary does), killed when dropped.
struct Gateways {
    children: Vec<Child>,
    /// Their JSON interfaces.
    json: Vec<String>,
}

/// Where gobyd says its JSON interface is, in its log line
/// `JSON interface on tcp://ADDRESS`.
fn json_address(log: &Path) -> Option<String> {
    let text = std::fs::read_to_string(log).ok()?;
    let at = text.find("JSON interface on tcp://")? + "JSON interface on tcp://".len();
    Some(text[at..].split_whitespace().next()?.to_string())
}

impl Gateways {
    fn start(configs: Vec<PathBuf>) -> Gateways {
        let mut children = Vec::new();
        let mut logs = Vec::new();
        for path in configs {
            let log_path = path.with_extension("log");
            let log = std::fs::File::create(&log_path).unwrap();
            children.push(
                Command::new(std::env::current_exe().unwrap())
                    .args([
                        "gateway_process",
                        "--exact",
                        "--ignored",
                        "--nocapture",
                        "--test-threads=1",
                    ])
                    .env("GOBY_CONSOLE_GATEWAY", &path)
                    .env_remove("RUST_BACKTRACE")
                    .stdin(Stdio::null())
                    .stdout(Stdio::null())
                    .stderr(log)
                    .spawn()
                    .expect("the gateway starts"),
            );
            logs.push(log_path);
        }
        let deadline = Instant::now() + broker::PATIENCE;
        let json = logs
            .iter()
            .map(|log| loop {
                if let Some(address) = json_address(log) {
                    break address;
                }
                assert!(
                    Instant::now() < deadline,
                    "the gateway did not start: {}",
                    std::fs::read_to_string(log).unwrap_or_default()
                );
                std::thread::sleep(Duration::from_millis(50));
            })
            .collect();
        Gateways { children, json }
    }
}

impl Drop for Gateways {
    fn drop(&mut self) {
        for child in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Not a test of its own: the gobyd process that the tests of this file
/// start, when this binary is run with `GOBY_CONSOLE_GATEWAY` naming its
/// configuration (`gobyd --config FILE`, until killed).
#[test]
#[ignore = "the gateway process of the other tests, run by them"]
fn gateway_process() {
    gobyd_child::run_gobyd_named_by("GOBY_CONSOLE_GATEWAY");
}

/// `goby console ARGS --listen 127.0.0.1:0`, killed when dropped.
struct Console {
    child: Child,
    /// `http://127.0.0.1:PORT/`.
    url: String,
}

impl Console {
    fn start(args: &[&str]) -> Console {
        let navigation = repo().join("protos/proto/goby/example/navigation.proto");
        let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
            .arg("console")
            .args(args)
            .arg("-f")
            .arg(navigation)
            .args(["--listen", "127.0.0.1:0"])
            .env_remove("RUST_BACKTRACE")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("goby console starts");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let url = line
            .split_whitespace()
            .find(|w| w.starts_with("http://"))
            .unwrap_or_else(|| panic!("no address in {line:?}"))
            .to_string();
        Console { child, url }
    }

    fn port(&self) -> u16 {
        self.url
            .trim_start_matches("http://127.0.0.1:")
            .trim_end_matches('/')
            .parse()
            .unwrap()
    }

    /// An HTTP/1.0 request to the console: status and JSON body.
    fn request(&self, method: &str, path: &str, body: Option<&Value>) -> (u16, Value) {
        let (status, text) = http(self.port(), method, path, body.map(Value::to_string));
        (
            status,
            serde_json::from_str(&text).unwrap_or(Value::String(text)),
        )
    }

    /// `GET /api/state` until `pick` gives something.
    fn wait_state<T>(
        &self,
        what: &str,
        patience: Duration,
        mut pick: impl FnMut(&Value) -> Option<T>,
    ) -> T {
        let deadline = Instant::now() + patience;
        loop {
            let (_, state) = self.request("GET", "/api/state", None);
            if let Some(t) = pick(&state) {
                return t;
            }
            assert!(
                Instant::now() < deadline,
                "timed out waiting for {what}: {state:#}"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for Console {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A plain HTTP/1.1 request on loopback: status and body.
fn http(port: u16, method: &str, path: &str, body: Option<String>) -> (u16, String) {
    try_http(port, method, path, body)
        .unwrap_or_else(|e| panic!("{method} {path} on port {port}: {e}"))
}

/// [`http`], with the error when the request could not be made.
fn try_http(
    port: u16,
    method: &str,
    path: &str,
    body: Option<String>,
) -> std::io::Result<(u16, String)> {
    let mut stream = TcpStream::connect(("127.0.0.1", port))?;
    stream.set_read_timeout(Some(broker::PATIENCE))?;
    let body = body.unwrap_or_default();
    let mut request =
        format!("{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n");
    if !body.is_empty() {
        request += &format!(
            "Content-Type: application/json\r\nContent-Length: {}\r\n",
            body.len()
        );
    }
    request += "\r\n";
    request += &body;
    stream.write_all(request.as_bytes())?;
    // The head, then as many bytes as it says (a server may keep the
    // connection open), or all until it closes.
    let mut reader = BufReader::new(stream);
    let mut head = String::new();
    let mut length = None;
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line)? == 0 || line == "\r\n" {
            break;
        }
        if let Some((name, value)) = line.split_once(':') {
            if name.eq_ignore_ascii_case("content-length") {
                length = value.trim().parse::<usize>().ok();
            }
        }
        head += &line;
    }
    let mut body = Vec::new();
    match length {
        Some(n) => {
            body.resize(n, 0);
            reader.read_exact(&mut body)?;
        }
        None => {
            reader.read_to_end(&mut body)?;
        }
    }
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    Ok((status, String::from_utf8_lossy(&body).into_owned()))
}

fn node<'a>(state: &'a Value, name: &str) -> Option<&'a Value> {
    state["nodes"]
        .as_array()?
        .iter()
        .find(|n| n["name"] == name)
}

/// A navigation report of vehicle `source` at `(x, y)`, to the other.
fn report(source: i64, x: f64, y: f64) -> Value {
    let time = (now_ms() / 1000.0).floor();
    json!({
        "source": source, "destination": 3 - source, "time": time, "x": x, "y": y,
        "z": -12, "heading": 90, "speed": 1.5, "veh_class": "AUV", "battery_ok": true,
    })
}

/// Each vehicle reports three positions on its `tx` topic.
fn report_positions(commander: &Watcher) {
    for i in 0..3 {
        let f = f64::from(i);
        commander.publish(
            "fleet/auv1/tx/goby.example.NavigationReport",
            report(1, 40.0 * f, 25.0 * f).to_string(),
        );
        commander.publish(
            "fleet/auv2/tx/goby.example.NavigationReport",
            report(2, 1500.0 - 30.0 * f, -35.0 * f).to_string(),
        );
    }
}

#[test]
fn the_console_serves_the_fleet_and_sends_commands() {
    let dir = scratch("api");
    let broker = Broker::start(&dir, "the_console_serves_the_fleet_and_sends_commands");
    let address = broker.address();
    let gateways = Gateways::start(fleet_configs(&dir, &address));
    let console = Console::start(&["fleet", "--broker", &address, "--origin", "41.52,-70.67"]);
    // The page and its assets are served from the binary.
    let (status, page) = http(console.port(), "GET", "/", None);
    assert_eq!(status, 200);
    assert!(page.contains("<script src=\"/console.js\">"), "{page}");
    for asset in ["/console.js", "/console.css", "/favicon.svg"] {
        let (status, body) = http(console.port(), "GET", asset, None);
        assert_eq!(status, 200, "{asset}");
        assert!(!body.is_empty(), "{asset}");
        // Nothing to fetch from elsewhere (the SVG namespace is a name, not a place).
        let body = body.replace("xmlns=\"http://www.w3.org/2000/svg\"", "");
        assert!(
            !body.contains("http://") && !body.contains("https://"),
            "{asset} names a remote place"
        );
    }
    assert_eq!(http(console.port(), "GET", "/nothing", None).0, 404);
    // The forms of the types loaded.
    let (_, forms) = console.request("GET", "/api/forms", None);
    let command = forms
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["name"] == "goby.example.Command")
        .expect("the Command form");
    assert_eq!(command["fields"][2]["max_repeat"], 3, "{command}");
    // Both gateways, from their retained status.
    console.wait_state("both gateways", broker::PATIENCE, |s| {
        let up =
            |n: &str| node(s, n).is_some_and(|n| n["online"] == true && n["driver"] == "ready");
        (up("auv1") && up("auv2")).then_some(())
    });
    let commander = Watcher::start(&address, "commander", "fleet/#");
    report_positions(&commander);
    let state = console.wait_state("both vehicles placed", broker::PATIENCE, |s| {
        let placed = |n: &str| {
            node(s, n).is_some_and(|n| n["track"].as_array().is_some_and(|t| t.len() == 3))
        };
        (placed("auv1") && placed("auv2")).then(|| s.clone())
    });
    let auv2 = node(&state, "auv2").unwrap();
    assert_eq!(auv2["position"]["x"], 1440.0, "{auv2}");
    assert!(
        (auv2["position"]["lat"].as_f64().unwrap() - 41.5197).abs() < 1e-3,
        "{auv2}"
    );
    // The check tells what the codec would change.
    let (_, checked) = console.request(
        "POST",
        "/api/check",
        Some(&json!({"type": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO", "note": "more than ten"}})),
    );
    assert_eq!(checked["changes"][0]["field"], "note", "{checked}");
    // Refused before sending: an unknown node, a message of the wrong form.
    let (status, refused) = console.request(
        "POST",
        "/api/send",
        Some(&json!({"node": "auv9", "type": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO"}})),
    );
    assert_eq!(status, 400);
    assert!(
        refused["error"].as_str().unwrap().contains("auv1, auv2"),
        "{refused}"
    );
    let (status, _) = console.request(
        "POST",
        "/api/send",
        Some(
            &json!({"node": "auv1", "type": "goby.example.Command", "msg": {"destination": "two"}}),
        ),
    );
    assert_eq!(status, 400);
    // Sent: published on auv1's tx topic, received by auv2, acked.
    let msg = json!({"destination": 2, "action": "GOTO", "waypoint": [{"x": 200, "y": -50}], "note": "survey A"});
    let (status, sent) = console.request(
        "POST",
        "/api/send",
        Some(&json!({"node": "auv1", "type": "goby.example.Command", "msg": msg})),
    );
    assert_eq!(status, 200, "{sent}");
    let id = sent["command"].as_u64().unwrap();
    commander.wait_for("the command on auv1's tx topic", |seen| match seen {
        Seen::Message(t, v)
            if t == "fleet/auv1/tx/goby.example.Command" && v["note"] == "survey A" =>
        {
            Some(())
        }
        _ => None,
    });
    let state = console.wait_state("the ack", LINK_PATIENCE, |s| {
        let c = s["commands"].as_array()?.iter().find(|c| c["id"] == id)?;
        (c["state"] == "acked").then(|| s.clone())
    });
    let c = state["commands"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["id"] == id)
        .unwrap();
    assert_eq!(c["note"], "by 2", "{c}");
    assert!(c["journal_id"].is_number(), "{c}");
    let received = state["messages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["kind"] == "rx" && m["node"] == "auv2" && m["type"] == "goby.example.Command")
        .unwrap_or_else(|| panic!("the command received at auv2: {}", state["messages"]));
    assert_eq!(received["msg"]["note"], "survey A", "{received}");
    assert_eq!(received["src"], 1);
    drop(console);

    // The same gateway through its JSON interface.
    let json = gateways.json[1].clone();
    let console = Console::start(&["--gobyd", &json, "--node", "auv2"]);
    console.wait_state("the JSON interface", broker::PATIENCE, |s| {
        (s["connection"]["connected"] == true && node(s, "auv2").is_some()).then_some(())
    });
    let (status, sent) = console.request(
        "POST",
        "/api/send",
        Some(&json!({"node": "auv2", "type": "goby.example.Command", "msg": {"destination": 1, "action": "HOLD"}})),
    );
    assert_eq!(status, 200, "{sent}");
    let id = sent["command"].as_u64().unwrap();
    console.wait_state("the JSON interface's ack", LINK_PATIENCE, |s| {
        let c = s["commands"].as_array()?.iter().find(|c| c["id"] == id)?;
        (c["state"] == "acked").then_some(())
    });
    drop(console);
    drop(gateways);
    let _ = std::fs::remove_dir_all(&dir);
}

/// The configuration at `path` (a quick start vehicle's) with a MAC
/// switcher in place of its `mac`: `survey`, the cycle it had (the
/// default), and `quiet`, whose second slot is twice as long.
fn with_mac_switcher(path: &Path) {
    let text = std::fs::read_to_string(path).unwrap();
    let start = text.find("\nmac {").expect("a mac section") + 1;
    let end = start + text[start..].find("\n}\n").expect("its end") + 3;
    let cycle = text[start + "mac {".len()..end - 3].replace('\n', " ");
    let switcher = format!(
        "mac_switcher {{\n  default_mac: \"survey\"\n  mac {{ name: \"survey\" mac {{{cycle} }} }}\n  \
         mac {{ name: \"quiet\" mac {{ type: MAC_FIXED_DECENTRALIZED \
         slot {{ src: 1 dest: -1 rate: 2 slot_seconds: 8 }} slot {{ src: 2 dest: -1 rate: 2 slot_seconds: 16 }} }} }}\n}}\n"
    );
    std::fs::write(
        path,
        format!("{}{switcher}{}", &text[..start], &text[end..]),
    )
    .unwrap();
}

/// The slots' sources and lengths of `node`'s cycle in a state.
fn cycle_of(state: &Value, name: &str) -> Option<Vec<(i64, f64)>> {
    let slots = node(state, name)?["mac"]["cycle"]["slots"].as_array()?;
    Some(
        slots
            .iter()
            .map(|s| (s["src"].as_i64().unwrap(), s["seconds"].as_f64().unwrap()))
            .collect(),
    )
}

/// Sends a MAC request to the console and waits for the answer of the
/// node: the command as it ends (applied or refused).
fn mac_request(console: &Console, body: &Value) -> Value {
    let (status, sent) = console.request("POST", "/api/mac", Some(body));
    assert_eq!(status, 200, "{body}: {sent}");
    let id = sent["command"].as_u64().unwrap();
    console.wait_state("the MAC request's answer", broker::PATIENCE, |s| {
        let c = s["commands"].as_array()?.iter().find(|c| c["id"] == id)?;
        (c["state"] != "published").then(|| c.clone())
    })
}

#[test]
fn the_console_shows_each_nodes_mac_and_changes_it() {
    let dir = scratch("mac");
    let broker = Broker::start(&dir, "the_console_shows_each_nodes_mac_and_changes_it");
    let address = broker.address();
    let configs = fleet_configs(&dir, &address);
    with_mac_switcher(&configs[1]);
    let gateways = Gateways::start(configs);
    let console = Console::start(&["fleet", "--broker", &address]);
    // From the retained topics each bridge publishes when it starts.
    let state = console.wait_state("both cycles and auv2's MAC", broker::PATIENCE, |s| {
        let cycles = cycle_of(s, "auv1").is_some() && cycle_of(s, "auv2").is_some();
        (cycles && node(s, "auv2")?["mac"]["active"].is_object()).then(|| s.clone())
    });
    assert_eq!(cycle_of(&state, "auv1").unwrap(), [(1, 8.0), (2, 8.0)]);
    let auv2 = &node(&state, "auv2").unwrap()["mac"];
    assert_eq!(auv2["active"]["name"], "survey", "{auv2}");
    assert_eq!(auv2["active"]["reason"], "started", "{auv2}");
    assert_eq!(node(&state, "auv1").unwrap()["mac"]["active"], Value::Null);

    // Bad input is refused by the console, saying what is wrong.
    for (body, said) in [
        (
            json!({"node": "auv1", "update": {"update_type": "SHUFFLE"}}),
            "SHUFFLE",
        ),
        (
            json!({"node": "auv1", "update": {"update_type": "ASSIGN", "slot": [{"slot_seconds": "long"}]}}),
            "MACUpdate",
        ),
        (
            json!({"node": "auv1", "switch": {"mac": "quiet", "keep_alive_seconds": 0}}),
            "keep_alive_seconds",
        ),
        (json!({"node": "auv1"}), "either"),
        (
            json!({"node": "auv9", "update": {"update_type": "CLEAR"}}),
            "auv1, auv2",
        ),
    ] {
        let (status, refused) = console.request("POST", "/api/mac", Some(&body));
        assert_eq!(status, 400, "{body}: {refused}");
        assert!(
            refused["error"].as_str().unwrap().contains(said),
            "{body}: {refused}"
        );
    }
    let (status, _) = console.request("POST", "/api/mac", Some(&json!({"update": {}})));
    assert_eq!(status, 422);

    // An update through the broker: applied, and the cycle shown changes.
    let assigned = mac_request(
        &console,
        &json!({"node": "auv1", "update": {"update_type": "ASSIGN", "slot": [
            {"src": 1, "dest": -1, "rate": 2, "slot_seconds": 8},
            {"src": 2, "dest": -1, "rate": 2, "slot_seconds": 8},
            {"src": 1, "dest": -1, "rate": 2, "slot_seconds": 12}]}}),
    );
    assert_eq!(assigned["state"], "applied", "{assigned}");
    assert_eq!(assigned["note"], "3 slots, running", "{assigned}");
    console.wait_state("auv1's new cycle", broker::PATIENCE, |s| {
        (cycle_of(s, "auv1")? == [(1, 8.0), (2, 8.0), (1, 12.0)]).then_some(())
    });
    // The simple kinds, and stopping the cycle.
    for (update, note) in [
        (json!({"update_type": "POP_BACK"}), "2 slots, running"),
        (
            json!({"update_type": "NO_CHANGE", "cycle_state": "STOPPED"}),
            "2 slots, stopped",
        ),
        (
            json!({"update_type": "PUSH_FRONT", "slot": [{"src": 2, "dest": -1, "rate": 2, "slot_seconds": 8}],
                   "cycle_state": "STARTED"}),
            "3 slots, running",
        ),
    ] {
        let answered = mac_request(&console, &json!({"node": "auv1", "update": update}));
        assert_eq!(
            (&answered["state"], &answered["note"]),
            (&json!("applied"), &json!(note)),
            "{update}: {answered}"
        );
    }
    console.wait_state("auv1's cycle pushed in front", broker::PATIENCE, |s| {
        (cycle_of(s, "auv1")? == [(2, 8.0), (1, 8.0), (2, 8.0)]).then_some(())
    });
    // One the node refuses, with its reason; the cycle stays.
    let refused = mac_request(
        &console,
        &json!({"node": "auv1", "update": {"update_type": "ERASE", "first_iterator": 9}}),
    );
    assert_eq!(refused["state"], "refused", "{refused}");
    assert!(refused["note"].as_str().unwrap().contains('9'), "{refused}");
    let cleared = mac_request(
        &console,
        &json!({"node": "auv1", "update": {"update_type": "CLEAR"}}),
    );
    assert_eq!(cleared["note"], "0 slots, stopped", "{cleared}");
    console.wait_state("auv1's cycle cleared", broker::PATIENCE, |s| {
        let mac = &node(s, "auv1")?["mac"]["cycle"];
        (mac["slots"].as_array()?.is_empty() && mac["running"] == false).then_some(())
    });
    // A switch, with a keep-alive.
    let switched = mac_request(
        &console,
        &json!({"node": "auv2", "switch": {"mac": "quiet", "keep_alive_seconds": 600}}),
    );
    assert_eq!(switched["state"], "applied", "{switched}");
    let state = console.wait_state("auv2 quiet, and its cycle", broker::PATIENCE, |s| {
        let quiet = node(s, "auv2")?["mac"]["active"]["name"] == "quiet";
        (quiet && cycle_of(s, "auv2")? == [(1, 8.0), (2, 16.0)]).then(|| s.clone())
    });
    assert_eq!(
        node(&state, "auv2").unwrap()["mac"]["cycle"]["from"],
        "switch"
    );
    let active = &node(&state, "auv2").unwrap()["mac"]["active"];
    assert_eq!(active["reason"], "requested", "{active}");
    assert!(
        active["keep_alive_until"].as_f64().unwrap() > now_ms() / 1000.0,
        "{active}"
    );
    drop(console);

    // auv2 through its JSON interface: asked at connection, changed by
    // requests whose replies answer them.
    let console = Console::start(&["--gobyd", &gateways.json[1], "--node", "auv2"]);
    let state = console.wait_state("auv2's MAC on its JSON interface", broker::PATIENCE, |s| {
        let mac = &node(s, "auv2")?["mac"];
        (mac["cycle"].is_object() && mac["active"].is_object()).then(|| s.clone())
    });
    assert_eq!(cycle_of(&state, "auv2").unwrap(), [(1, 8.0), (2, 16.0)]);
    let active = &node(&state, "auv2").unwrap()["mac"]["active"];
    assert_eq!(active["name"], "quiet", "{active}");
    assert_eq!(active["macs"], json!(["survey", "quiet"]), "{active}");
    let pushed = mac_request(
        &console,
        &json!({"node": "auv2", "update": {"update_type": "PUSH_BACK",
            "slot": [{"src": 2, "dest": -1, "rate": 2, "slot_seconds": 8}]}}),
    );
    assert_eq!(pushed["state"], "applied", "{pushed}");
    console.wait_state("auv2's cycle pushed", broker::PATIENCE, |s| {
        (cycle_of(s, "auv2")? == [(1, 8.0), (2, 16.0), (2, 8.0)]).then_some(())
    });
    let loud = mac_request(
        &console,
        &json!({"node": "auv2", "switch": {"mac": "loud"}}),
    );
    assert_eq!(loud["state"], "refused", "{loud}");
    assert!(loud["note"].as_str().unwrap().contains("loud"), "{loud}");
    drop(console);
    drop(gateways);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[cfg_attr(
    not(chromium),
    ignore = "Chromium is not installed: `bash .ci/chromium.sh` installs Debian's package (the README's test command runs it)"
)]
fn the_page_shows_the_fleet_and_commands_it() {
    #[cfg(chromium)]
    browser::run();
}

/// The commander as the page opens, before anything was typed: the form of
/// the first type is drawn and its check has run, but no error is shown
/// (the empty form of a type with required fields cannot be encoded, which
/// is no news to a user who has typed nothing); once a field was typed, the
/// error shows.
#[test]
#[cfg_attr(
    not(chromium),
    ignore = "Chromium is not installed: `bash .ci/chromium.sh` installs Debian's package (the README's test command runs it)"
)]
fn the_commander_opens_without_an_error() {
    #[cfg(chromium)]
    browser::opens_without_an_error();
}

/// A screenshot taken by headless Chromium on its command line with a
/// virtual time budget, as `docs/console.md` gives it: the page at
/// `?static` draws one snapshot and opens no event stream, so the browser
/// finds the network quiet, spends its budget and returns (with the stream
/// open it waits forever). The page's text at the end of the same budget
/// shows the snapshot drawn.
#[test]
#[cfg_attr(
    not(chromium),
    ignore = "Chromium is not installed: `bash .ci/chromium.sh` installs Debian's package (the README's test command runs it)"
)]
fn a_headless_screenshot_with_a_virtual_time_budget_returns() {
    #[cfg(chromium)]
    browser::screenshot_returns();
}

/// A `goby sim` run replayed on the page: the page's clock is the run's
/// (the header says the run's time, ages are counted from it), the AUVs
/// move along their tracks, and the commander says a replay takes no
/// commands.
#[test]
#[cfg_attr(
    not(chromium),
    ignore = "Chromium is not installed: `bash .ci/chromium.sh` installs Debian's package (the README's test command runs it)"
)]
fn a_replay_plays_on_the_page_in_the_run_s_time() {
    #[cfg(chromium)]
    browser::replay_plays();
}

#[cfg(chromium)]
mod browser {
    use super::*;

    /// A Chrome DevTools protocol client of one page: commands by id, their
    /// results awaited (events in between skipped).
    mod devtools {
        use std::net::TcpStream;
        use std::time::{Duration, Instant};

        use serde_json::{json, Value};
        use tungstenite::{Message, WebSocket};

        pub struct Page {
            socket: WebSocket<TcpStream>,
            next: u64,
        }

        impl Page {
            /// Connects to a page's `webSocketDebuggerUrl`.
            pub fn connect(url: &str) -> Page {
                let rest = url.trim_start_matches("ws://");
                let host = rest.split('/').next().unwrap();
                let stream = TcpStream::connect(host).unwrap();
                stream
                    .set_read_timeout(Some(Duration::from_secs(60)))
                    .unwrap();
                let (socket, _) = tungstenite::client(url, stream).expect("the DevTools handshake");
                Page { socket, next: 1 }
            }

            /// Calls `method` and waits for its result.
            pub fn call(&mut self, method: &str, params: Value) -> Value {
                let id = self.next;
                self.next += 1;
                let text = json!({"id": id, "method": method, "params": params}).to_string();
                self.socket.send(Message::text(text)).unwrap();
                loop {
                    let message = self.socket.read().expect("a DevTools message");
                    let Message::Text(text) = message else {
                        continue;
                    };
                    let value: Value = serde_json::from_str(&text).unwrap();
                    if value["id"] == id {
                        assert!(value.get("error").is_none(), "{method}: {value}");
                        return value["result"].clone();
                    }
                }
            }

            /// Evaluates `expression` in the page (promises awaited): its value.
            pub fn eval(&mut self, expression: &str) -> Value {
                let result = self.call(
                    "Runtime.evaluate",
                    json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
                );
                assert!(
                    result.get("exceptionDetails").is_none(),
                    "{expression}: {result}"
                );
                result["result"]["value"].clone()
            }

            /// Evaluates `expression` every 100 ms until it is true.
            pub fn wait(&mut self, what: &str, expression: &str, patience: Duration) {
                let deadline = Instant::now() + patience;
                loop {
                    if self.eval(expression) == Value::Bool(true) {
                        return;
                    }
                    if Instant::now() > deadline {
                        let state = self.eval("JSON.stringify({errors: goby.errors, map: goby.map, commands: [...goby.state.commands.values()]})");
                        panic!("timed out waiting for {what} ({expression}): {state}");
                    }
                    std::thread::sleep(Duration::from_millis(100));
                }
            }

            /// A PNG of what the window shows, scaled by `scale`.
            pub fn screenshot_window(&mut self, scale: f64) -> Vec<u8> {
                use base64::Engine;
                let size = self.eval("[window.innerWidth, window.innerHeight]");
                let shot = self.call(
                "Page.captureScreenshot",
                json!({"format": "png",
                       "clip": {"x": 0, "y": 0, "width": size[0], "height": size[1], "scale": scale}}),
            );
                base64::engine::general_purpose::STANDARD
                    .decode(shot["data"].as_str().unwrap())
                    .unwrap()
            }

            /// A PNG of the whole page.
            pub fn screenshot(&mut self) -> Vec<u8> {
                use base64::Engine;
                let metrics = self.call("Page.getLayoutMetrics", json!({}));
                let size = &metrics["cssContentSize"];
                let shot = self.call(
                "Page.captureScreenshot",
                json!({"format": "png", "captureBeyondViewport": true,
                       "clip": {"x": 0, "y": 0, "width": size["width"], "height": size["height"], "scale": 1}}),
            );
                base64::engine::general_purpose::STANDARD
                    .decode(shot["data"].as_str().unwrap())
                    .unwrap()
            }
        }
    }

    /// Headless Chromium with a DevTools port, killed when dropped.
    struct Chromium {
        child: Child,
        port: u16,
    }

    /// The flags of every headless Chromium of these tests: no sandbox (a
    /// container's root), no GPU, no first-run pages, a laptop's window.
    const HEADLESS: [&str; 6] = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--hide-scrollbars",
        "--window-size=1366,900",
    ];

    impl Chromium {
        fn start(profile: &Path) -> Chromium {
            let mut child = Command::new(env!("GOBY_CHROMIUM_PATH"))
                .args(HEADLESS)
                .args([
                    "--no-default-browser-check",
                    "--disable-extensions",
                    "--disable-background-networking",
                    "--disable-component-update",
                    "--disable-sync",
                    "--remote-debugging-address=127.0.0.1",
                    "--remote-debugging-port=0",
                ])
                .arg(format!("--user-data-dir={}", profile.display()))
                .arg("about:blank")
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .expect("chromium starts");
            let stderr = child.stderr.take().unwrap();
            let (found, port) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                let mut found = Some(found);
                for line in BufReader::new(stderr).lines() {
                    let Ok(line) = line else { break };
                    if let Some(rest) = line.split("DevTools listening on ws://127.0.0.1:").nth(1) {
                        let port: u16 = rest.split('/').next().unwrap().parse().unwrap();
                        if let Some(found) = found.take() {
                            let _ = found.send(port);
                        }
                    }
                    // The rest is read and dropped, so that the pipe never fills.
                }
            });
            let port = port
                .recv_timeout(broker::PATIENCE)
                .expect("chromium names its DevTools port");
            Chromium { child, port }
        }

        /// The page's DevTools client.
        fn page(&self) -> devtools::Page {
            let deadline = Instant::now() + broker::PATIENCE;
            loop {
                let list = try_http(self.port, "GET", "/json/list", None)
                    .ok()
                    .and_then(|(_, list)| serde_json::from_str::<Value>(&list).ok())
                    .unwrap_or(Value::Null);
                if let Some(url) = list
                    .as_array()
                    .and_then(|l| l.iter().find(|t| t["type"] == "page"))
                    .and_then(|t| t["webSocketDebuggerUrl"].as_str())
                {
                    return devtools::Page::connect(url);
                }
                assert!(Instant::now() < deadline, "no page in {list}");
                std::thread::sleep(Duration::from_millis(100));
            }
        }
    }

    impl Drop for Chromium {
        fn drop(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    /// Where the screenshots and measurements are kept.
    fn artifacts() -> PathBuf {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("console");
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Sets an input of the commander's form (by its `data-path`) as typing
    /// would, and waits for the page's check of the draft.
    fn fill(page: &mut devtools::Page, path: &str, value: &str) {
        let expression = format!(
        "(() => {{ const e = document.querySelector('#cmd-fields [data-path=\"{path}\"]'); \
         if (!e) return false; e.value = {value}; \
         e.dispatchEvent(new Event(e.tagName === 'SELECT' ? 'change' : 'input', {{bubbles: true}})); return true; }})()",
        value = json!(value)
    );
        assert_eq!(page.eval(&expression), Value::Bool(true), "no input {path}");
    }

    /// Waits until the page's last check is of the form as it stands (the
    /// check runs 150 ms after the last input), and returns it.
    fn checked(page: &mut devtools::Page) -> Value {
        page.wait(
            "the check of the draft",
            "goby.checkedDraft === JSON.stringify(goby.draft())",
            broker::PATIENCE,
        );
        page.eval("goby.lastCheck")
    }

    /// Runs headless Chromium on its command line with `args` and the
    /// page at `url`: its standard output, or a panic if it has not
    /// returned within [`broker::PATIENCE`].
    fn headless(profile: &Path, args: &[String], url: &str) -> String {
        let mut child = Command::new(env!("GOBY_CHROMIUM_PATH"))
            .args(HEADLESS)
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(args)
            .arg(url)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("chromium starts");
        let mut stdout = child.stdout.take().unwrap();
        let reader = std::thread::spawn(move || {
            let mut text = String::new();
            let _ = stdout.read_to_string(&mut text);
            text
        });
        let started = Instant::now();
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                assert!(status.success(), "chromium {args:?} {url}: {status}");
                return reader.join().unwrap();
            }
            if started.elapsed() > broker::PATIENCE {
                let _ = child.kill();
                let _ = child.wait();
                panic!(
                    "chromium {args:?} {url} had not returned after {:?}",
                    broker::PATIENCE
                );
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    pub fn screenshot_returns() {
        let dir = scratch("browser-screenshot");
        let broker = Broker::start(&dir, "a_headless_screenshot_returns");
        let console = Console::start(&["fleet", "--broker", &broker.address()]);
        let url = format!("{}?static", console.url);
        let shot = dir.join("console.png");
        let budget = "--virtual-time-budget=5000".to_string();
        headless(
            &dir.join("profile"),
            &[format!("--screenshot={}", shot.display()), budget.clone()],
            &url,
        );
        let png = std::fs::read(&shot).expect("the screenshot is written");
        assert!(png.starts_with(b"\x89PNG"), "not a PNG");
        std::fs::write(artifacts().join("static.png"), &png).unwrap();
        let dom = headless(&dir.join("profile"), &["--dump-dom".into(), budget], &url);
        assert!(
            dom.contains("fleet/ on the MQTT broker") && dom.contains("a still picture"),
            "the snapshot is not drawn: {dom}"
        );
        assert!(dom.contains("goby.example.Command"), "no commander: {dom}");
        drop(console);
        drop(broker);
        let _ = std::fs::remove_dir_all(&dir);
    }

    pub fn replay_plays() {
        let dir = scratch("browser-replay");
        let survey = repo().join("sim/examples/survey.pb.txt");
        let run = Command::new(env!("CARGO_BIN_EXE_goby"))
            .args(["sim", survey.to_str().unwrap(), "--out"])
            .arg(dir.join("run"))
            .output()
            .unwrap();
        assert!(run.status.success(), "{run:?}");
        let replay = dir.join("run/replay.jsonl");
        // The run's 9 000 s in 3 s.
        let console = Console::start(&["--replay", replay.to_str().unwrap(), "--warp", "3000"]);
        let chromium = Chromium::start(&dir.join("profile"));
        let mut page = chromium.page();
        page.call("Page.enable", json!({}));
        page.call("Page.navigate", json!({"url": console.url}));
        // 2026-06-01T02:30:00Z, the run's end.
        page.wait(
            "the replay's end",
            "typeof goby === 'object' && goby.state.clock === 1780281000 \
             && goby.state.connection.connected === false",
            broker::PATIENCE,
        );
        // The pill is drawn at the page's next frame after the state
        // changed: waited for, then compared (a mismatch shows its text).
        let ended = "run time 2026-06-01 02:30:00 UTC; the replay has ended (the run's end)";
        page.wait(
            "the pill of the replay's end",
            &format!("document.getElementById('connection').textContent === {ended:?}"),
            broker::PATIENCE,
        );
        let pill = page.eval("document.getElementById('connection').textContent");
        assert_eq!(pill, json!(ended));
        // Ages in the run's time: the ship was last heard as the traffic
        // ended, 30 minutes of drain before the run's end (not 56 years
        // ago, as a wall clock would say).
        let heard = page.eval(
            "(() => { const n = goby.state.nodes.get('ship'); return goby.state.clock - n.last_heard; })()",
        );
        assert!(
            heard
                .as_f64()
                .is_some_and(|s| (1800.0..2400.0).contains(&s)),
            "{heard}"
        );
        // auv1 moved to its last point at the end, but was last heard as
        // the traffic ended: its age on the page is from then.
        let auv1 = page.eval(
            "(() => { const n = goby.state.nodes.get('auv1'); return goby.state.clock - n.last_heard; })()",
        );
        assert!(auv1.as_f64().is_some_and(|s| s > 1700.0), "{auv1}");
        let track = page.eval("goby.state.nodes.get('auv1').track.length");
        assert!(track.as_u64().is_some_and(|n| n > 800), "{track}");
        assert_eq!(
            page.eval("document.getElementById('cmd-send').disabled"),
            Value::Bool(true)
        );
        assert_eq!(
            page.eval("document.getElementById('cmd-said').textContent"),
            json!("a replay takes no commands")
        );
        assert_eq!(page.eval("goby.errors"), json!([]));
        drop(page);
        drop(chromium);
        drop(console);
        let _ = std::fs::remove_dir_all(&dir);
    }

    pub fn opens_without_an_error() {
        let dir = scratch("browser-quiet");
        let broker = Broker::start(&dir, "the_commander_opens_without_an_error");
        let console = Console::start(&["fleet", "--broker", &broker.address()]);
        let chromium = Chromium::start(&dir.join("profile"));
        let mut page = chromium.page();
        page.call("Page.enable", json!({}));
        page.call("Page.navigate", json!({"url": console.url}));
        page.wait(
            "the commander's form and its first check",
            "typeof goby === 'object' && document.querySelector('#cmd-fields [data-path]') !== null \
             && goby.checkedDraft === JSON.stringify(goby.draft())",
            broker::PATIENCE,
        );
        // The first type's empty form cannot be encoded ...
        assert_eq!(page.eval("goby.lastCheck.ok"), Value::Bool(false));
        // ... but nothing typed, nothing is said against it.
        let shown = page.eval(
            "(() => { const b = document.getElementById('cmd-check'); \
             return {bad: b.classList.contains('bad'), text: b.textContent}; })()",
        );
        assert_eq!(shown["bad"], Value::Bool(false), "{shown}");
        assert!(
            !shown["text"]
                .as_str()
                .unwrap()
                .contains("Cannot be encoded"),
            "{shown}"
        );
        assert_eq!(
            page.eval("document.getElementById('cmd-send').disabled"),
            Value::Bool(true)
        );
        // Typed into (the note, with the destination still unset), the
        // form says what is wrong.
        assert_eq!(
            page.eval("goby.draft().type"),
            json!("goby.example.Command")
        );
        fill(&mut page, "note", "survey");
        let check = checked(&mut page);
        assert_eq!(check["ok"], Value::Bool(false), "{check}");
        let shown = page.eval("document.getElementById('cmd-check').className");
        assert_eq!(shown, json!("check bad"));
        assert_eq!(page.eval("goby.errors"), json!([]));
        drop(page);
        drop(chromium);
        drop(console);
        drop(broker);
        let _ = std::fs::remove_dir_all(&dir);
    }

    pub fn run() {
        let dir = scratch("browser");
        let out = artifacts();
        let broker = Broker::start(&dir, "the_page_shows_the_fleet_and_commands_it");
        let address = broker.address();
        let gateways = Gateways::start(fleet_configs(&dir, &address));
        let console = Console::start(&["fleet", "--broker", &address, "--origin", "41.52,-70.67"]);
        console.wait_state("both gateways", broker::PATIENCE, |s| {
            (node(s, "auv1").is_some() && node(s, "auv2").is_some()).then_some(())
        });
        let commander = Watcher::start(&address, "commander", "fleet/#");
        let chromium = Chromium::start(&dir.join("profile"));
        let mut page = chromium.page();
        page.call("Page.enable", json!({}));
        page.call("Runtime.enable", json!({}));

        // Load time: navigation start to the first snapshot drawn, several
        // loads (the first warms the browser's own caches).
        let mut loads = Vec::new();
        for _ in 0..4 {
            page.call("Page.navigate", json!({"url": console.url}));
            page.wait(
            "the page drawn",
            "typeof goby === 'object' && goby.readyAt !== null && document.readyState === 'complete'",
            broker::PATIENCE,
        );
            let t = page.eval(
            "(() => { const n = performance.getEntriesByType('navigation')[0]; \
             return {ready: goby.readyAt, load: n.loadEventEnd, dom: n.domContentLoadedEventEnd}; })()",
        );
            loads.push(t);
        }
        page.wait(
            "both gateways in the table",
            "document.querySelectorAll('#nodes tbody tr').length === 2",
            broker::PATIENCE,
        );

        // The map shows both nodes from the reports they send.
        report_positions(&commander);
        page.wait(
        "both nodes on the map",
        "goby.map && goby.map.placed === 2 && [...goby.state.nodes.values()].every(n => n.track.length === 3)",
        broker::PATIENCE,
    );
        let rows =
            page.eval("[...document.querySelectorAll('#nodes tbody tr')].map(r => r.textContent)");
        let rows = rows.as_array().unwrap();
        assert!(
            rows.iter().any(|r| r.as_str().unwrap().contains("auv2")
                && r.as_str().unwrap().contains("1440.0, -70.0 m")),
            "{rows:?}"
        );

        // A reception with a Micro-Modem's statistics, as a gateway on a
        // Micro-Modem publishes them, for the link plots.
        for (i, snr) in [(0, 11.0), (1, 8.5), (2, 13.0)] {
            let time = now_ms() / 1000.0 - 30.0 + f64::from(i) * 10.0;
            commander.publish(
            "fleet/auv2/link",
            json!({"src": 1, "dest": 2, "rate": 1, "frames": 2, "time": time,
                   "receive_stat": [{"snr_in": snr, "snr_out": snr - 3.0, "snr_rss": snr + 2.0,
                                     "doppler": -0.3 + 0.2 * f64::from(i), "number_bad_frames": i % 2, "number_frames": 2}]})
            .to_string(),
        );
        }
        page.wait(
            "the link series",
            "goby.state.nodes.get('auv2').links.filter(l => l.snr_in !== undefined).length === 3",
            broker::PATIENCE,
        );
        page.eval("(() => { document.querySelector('#nodes tbody tr[data-node=\"auv2\"]').click(); return true; })()");
        std::thread::sleep(Duration::from_millis(300));
        let laptop = page.screenshot();
        std::fs::write(out.join("laptop-map.png"), &laptop).unwrap();

        // The commander: auv1, a Command, filled in the form.
        page.eval("(() => { const n = document.getElementById('cmd-node'); n.value = 'auv1'; n.dispatchEvent(new Event('change')); \
               const t = document.getElementById('cmd-type'); t.value = 'goby.example.Command'; t.dispatchEvent(new Event('change')); return true; })()");
        fill(&mut page, "destination", "2");
        fill(&mut page, "action", "GOTO");
        assert_eq!(
        page.eval("(() => { document.querySelector('#cmd-fields [data-add=\"waypoint\"]').click(); return true; })()"),
        Value::Bool(true)
    );
        fill(&mut page, "waypoint[0].x", "200.4");
        fill(&mut page, "waypoint[0].y", "-50");
        fill(&mut page, "note", "survey A and B");
        // What the codec would change, before sending: the note truncated,
        // the waypoint rounded to the metre.
        let check = checked(&mut page);
        assert_eq!(check["changes"][0]["field"], "note", "{check}");
        assert_eq!(check["back"]["waypoint"][0]["x"], 200.0, "{check}");
        let shown = page.eval("document.getElementById('cmd-check').textContent");
        assert!(
            shown
                .as_str()
                .unwrap()
                .contains("note: string of 14 bytes longer than max_length 10"),
            "{shown}"
        );
        assert!(
            shown
                .as_str()
                .unwrap()
                .contains("waypoint[0].x: 200.4 → 200"),
            "{shown}"
        );
        assert_eq!(
        page.eval("document.querySelector('#cmd-fields [data-path=\"note\"]').classList.contains('changed')"),
        Value::Bool(true)
    );
        std::fs::write(out.join("commander-check.png"), page.screenshot()).unwrap();
        fill(&mut page, "note", "survey A");
        let check = checked(&mut page);
        assert_eq!(check["changes"], json!([]), "{check}");
        page.eval("(() => { document.getElementById('cmd-send').click(); return true; })()");
        page.wait(
            "the command sent",
            "goby.lastSend !== undefined && goby.lastSend.command !== undefined",
            broker::PATIENCE,
        );
        let id = page.eval("goby.lastSend.command");
        // It arrives at the other node ...
        let arrived = commander.wait_for("the command at auv2", |seen| match seen {
            Seen::Message(t, v)
                if t == "fleet/auv2/rx/goby.example.Command" && v["msg"]["note"] == "survey A" =>
            {
                Some(v.clone())
            }
            _ => None,
        });
        assert_eq!(arrived["msg"]["waypoint"][0]["x"], 200.0, "{arrived}");
        assert_eq!(arrived["src"], 1);
        // ... and its ack shows in the page.
        page.wait(
        "the ack in the page",
        &format!("(() => {{ const r = document.querySelector('#commands tr[data-command=\"{id}\"] .state-acked'); return r !== null; }})()"),
        LINK_PATIENCE,
    );
        let row = page.eval(&format!(
            "document.querySelector('#commands tr[data-command=\"{id}\"]').textContent"
        ));
        assert!(row.as_str().unwrap().contains("by 2"), "{row}");
        let fields = page.eval("[...document.querySelectorAll('#messages tbody tr')].map(r => r.textContent).join('\\n')");
        assert!(
            fields.as_str().unwrap().contains("note: survey A"),
            "{fields}"
        );
        std::fs::write(out.join("laptop-acked.png"), page.screenshot()).unwrap();

        // Medium access: auv1's cycle as its bridge published it, then
        // changed from the form (bad input first, answered by the server).
        page.eval("(() => { document.querySelector('#nodes tbody tr[data-node=\"auv1\"]').click(); return true; })()");
        page.wait(
            "auv1's cycle in the page",
            "document.getElementById('mac-name').textContent === 'auv1' \
             && document.querySelectorAll('#mac-bar > div').length === 2",
            broker::PATIENCE,
        );
        let slots = "[...document.querySelectorAll('#mac-cycle tbody tr')]\
            .map(r => [...r.cells].slice(0, 5).map(c => c.textContent).join(' '))";
        assert_eq!(page.eval(slots), json!(["0 1 -1 2 8.0", "1 2 -1 2 8.0"]));
        let send_mac = |page: &mut devtools::Page, slots: &str| {
            let expression = format!(
                "(() => {{ goby.lastMac = undefined; const k = document.getElementById('mac-kind'); \
                 k.value = 'ASSIGN'; k.dispatchEvent(new Event('change')); \
                 document.getElementById('mac-slots').value = {slots}; \
                 document.getElementById('mac-send').click(); return true; }})()",
                slots = json!(slots)
            );
            page.eval(&expression);
            page.wait(
                "the console's answer",
                "goby.lastMac !== undefined",
                broker::PATIENCE,
            );
        };
        send_mac(&mut page, "1 -1 2 8\n2 -1 2 long");
        let said = page.eval("[document.getElementById('mac-said').className, document.getElementById('mac-said').textContent]");
        assert_eq!(said[0], "bad", "{said}");
        assert!(said[1].as_str().unwrap().contains("MACUpdate"), "{said}");
        send_mac(&mut page, "1 -1 2 8\n2 -1 2 8\n1 -1 2 12");
        page.wait(
            "the new cycle in the page",
            "document.querySelectorAll('#mac-bar > div').length === 3 \
             && document.getElementById('mac-said').className === 'good'",
            broker::PATIENCE,
        );
        assert_eq!(
            page.eval(slots),
            json!(["0 1 -1 2 8.0", "1 2 -1 2 8.0", "2 1 -1 2 12.0"])
        );
        let said = page.eval("document.getElementById('mac-said').textContent");
        assert_eq!(said, json!("mac_update to auv1: applied: 3 slots, running"));
        std::fs::write(out.join("mac.png"), page.screenshot()).unwrap();
        // The guide's picture (docs/console.md): a laptop's window, a little
        // taller so that the commander's acked command shows, auv2 picked.
        page.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": 1366, "height": 1230, "deviceScaleFactor": 1, "mobile": false}),
        );
        page.eval("(() => { document.querySelector('#nodes tbody tr[data-node=\"auv2\"]').click(); window.scrollTo(0, 0); return true; })()");
        std::thread::sleep(Duration::from_millis(300));
        std::fs::write(out.join("guide.png"), page.screenshot_window(0.6)).unwrap();

        // Update latency: a publication on the broker to its row drawn.
        let mut latencies = Vec::new();
        for i in 0..20 {
            let marker = format!("lat-{i:02}");
            let sent = now_ms();
            commander.publish(
                "fleet/auv2/rx/goby.example.Command",
                json!({"type": "goby.example.Command", "src": 1, "dest": 2, "time": sent / 1000.0,
                   "msg": {"destination": 2, "action": "HOLD", "note": marker}})
                .to_string(),
            );
            let expression = format!(
            "(() => {{ const m = goby.state.messages.find(m => m.msg && m.msg.note === '{marker}'); \
             return m !== undefined && goby.shownAt[m.seq] !== undefined; }})()"
        );
            page.wait("the message shown", &expression, broker::PATIENCE);
            let shown = page.eval(&format!(
            "goby.shownAt[goby.state.messages.find(m => m.msg && m.msg.note === '{marker}').seq]"
        ));
            latencies.push(shown.as_f64().unwrap() - sent);
            std::thread::sleep(Duration::from_millis(50));
        }

        // A tablet: one column, nothing wider than the screen.
        page.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": 820, "height": 1180, "deviceScaleFactor": 1, "mobile": true}),
        );
        std::thread::sleep(Duration::from_millis(500));
        let overflow = page.eval("document.documentElement.scrollWidth - window.innerWidth");
        assert!(
            overflow.as_f64().unwrap() <= 0.0,
            "wider than a tablet by {overflow} px"
        );
        std::fs::write(out.join("tablet.png"), page.screenshot()).unwrap();
        assert_eq!(page.eval("goby.errors"), json!([]));

        let mut sorted = latencies.clone();
        sorted.sort_by(f64::total_cmp);
        let ready: Vec<f64> = loads.iter().map(|l| l["ready"].as_f64().unwrap()).collect();
        let measured = json!({
            "load_ms": {"first_snapshot_drawn": ready, "load_event_end": loads.iter().map(|l| l["load"].clone()).collect::<Vec<_>>()},
            "update_latency_ms": {"median": sorted[sorted.len() / 2], "max": sorted[sorted.len() - 1], "all": latencies},
        });
        std::fs::write(out.join("measured.json"), format!("{measured:#}\n")).unwrap();
        eprintln!("console measurements ({}): {measured}", out.display());
        assert!(
            sorted[sorted.len() - 1] < 5000.0,
            "a publication took over 5 s to show: {latencies:?}"
        );
        drop(page);
        drop(chromium);
        drop(console);
        drop(gateways);
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// A request written as is (`text`, head and body) to the console: status
/// and body (HTTP/1.0, so the body ends with the connection).
fn raw_http(port: u16, text: &str) -> (u16, String) {
    let mut stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream.set_read_timeout(Some(broker::PATIENCE)).unwrap();
    stream.write_all(text.as_bytes()).unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).unwrap();
    let (head, body) = response.split_once("\r\n\r\n").unwrap_or((&response, ""));
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    (status, body.to_string())
}

/// What docs/console.md says of the interface: the POST bodies are JSON
/// with `Content-Type: application/json` (else status 415), with the keys
/// named (else 422), and each object of the event stream names its kind
/// in `event`, the snapshot first. Needs no broker: the source is a
/// gobyd's JSON interface, not there.
#[test]
fn the_interface_takes_json_bodies_and_names_each_events_kind() {
    let console = Console::start(&["--gobyd", "127.0.0.1:9", "--duration", "120"]);
    let port = console.port();
    let draft =
        json!({"type": "goby.example.Command", "msg": {"destination": 2, "action": "GOTO"}})
            .to_string();
    let post = |head: &str, body: &str| {
        raw_http(
            port,
            &format!(
                "POST /api/check HTTP/1.0\r\nHost: 127.0.0.1\r\n{head}Content-Length: {}\r\n\r\n{body}",
                body.len()
            ),
        )
    };
    let (status, said) = post("", &draft);
    assert_eq!(status, 415, "{said}");
    assert!(said.contains("Content-Type: application/json"), "{said}");
    let (status, said) = post("Content-Type: text/plain\r\n", &draft);
    assert_eq!(status, 415, "{said}");
    let (status, checked) = post("Content-Type: application/json\r\n", &draft);
    assert_eq!(status, 200, "{checked}");
    let checked: Value = serde_json::from_str(&checked).unwrap();
    assert!(
        checked["bytes"].is_string() || checked["bytes"].is_number(),
        "{checked}"
    );
    let (status, said) = post(
        "Content-Type: application/json\r\n",
        r#"{"msg": {"destination": 2}}"#,
    );
    assert_eq!(status, 422, "{said}");
    assert!(said.contains("missing field `type`"), "{said}");
    let (status, said) = post("Content-Type: application/json\r\n", "{not json");
    assert_eq!(status, 400, "{said}");

    // The event stream: `data:` lines, one JSON object each; the first is
    // the snapshot, tagged as such, with the source's connection.
    let mut stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream.set_read_timeout(Some(broker::PATIENCE)).unwrap();
    stream
        .write_all(b"GET /api/events HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n")
        .unwrap();
    let mut lines = BufReader::new(stream).lines();
    let first = lines
        .by_ref()
        .map_while(Result::ok)
        .find_map(|l| l.strip_prefix("data:").map(|d| d.trim().to_string()))
        .expect("a data line");
    let snapshot: Value = serde_json::from_str(&first).unwrap();
    assert_eq!(snapshot["event"], "snapshot", "{snapshot}");
    assert!(
        snapshot["connection"]["connected"].is_boolean(),
        "{snapshot}"
    );
    assert!(snapshot["seq"].is_u64(), "{snapshot}");
}
