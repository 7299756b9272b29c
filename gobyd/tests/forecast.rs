//! The link forecast (GRAM): a daemon keeping an environment — the summer
//! (GLINT10-like) water of a BELLHOP .env, a profile from CTD samples —
//! answers a JSON `forecast` request with the SNR and frame-error rates to
//! its peer and the recommended depth in its band; bad samples are refused
//! by name and the last good environment kept; a bad `forecast` section is
//! refused by `--check` naming the field or the file and line; on MOOS the
//! forecast arrives as the variables an IvP Helm behaviour takes (with the
//! minimal in-process DB always, with a real MOOSDB when on the PATH); on
//! MQTT it is retained for the console.

mod support;

use std::path::Path;
use std::time::Duration;

use gobyd::daemon::Daemon;
use moos::{ClientConfig, MoosClient, Value as MoosValue};
use serde_json::{json, Value};
use support::broker::{Broker, Watcher};
use support::daemon::scratch;
use support::moosdb::{moosdb_on_path, RealMoosDb};
use support::node::{Entry, Node, Simulator};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;
use tokio::sync::oneshot;

const PATIENCE: Duration = Duration::from_secs(60);

/// A file of the channel crate's test data.
fn data(file: &str) -> String {
    format!(
        "{}/../channel/tests/data/{file}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// A `forecast` section in the summer water: this vehicle at 3 km from
/// the buoy (node 2, moored at 30 m), in the surface layer (6 m).
fn forecast_section(more: &str) -> String {
    format!(
        r#"forecast {{
  water {{ env: "{}" beams: 300 }}
  own {{ x: 3000 y: 0 depth: 6 }}
  peer {{ modem_id: 2 position {{ x: 0 y: 0 depth: 30 }} }}
  band_shallow: 2 band_deep: 100 depth_step: 4 rate: 1
  min_interval_seconds: 0.5
  {more}
}}"#,
        data("bellhop/summer.env")
    )
}

fn node(dir: &Path, name: &str, forecast: &str) -> Node {
    Node::new(1)
        .driver(Simulator::alone().channel(name))
        .mac_none()
        .json_tcp("127.0.0.1:0")
        .data_dir(&dir.join("data"))
        .raw_log(false)
        .extra(forecast)
}

/// A running daemon and a JSON client of it.
struct Running {
    lines: tokio::io::Lines<BufReader<tokio::net::tcp::OwnedReadHalf>>,
    /// Lines read past while waiting for another (events before a reply).
    held: std::collections::VecDeque<Value>,
    write: tokio::net::tcp::OwnedWriteHalf,
    stop: oneshot::Sender<()>,
    running: tokio::task::JoinHandle<Result<(), gobyd::error::DaemonError>>,
}

impl Running {
    async fn start(node: Node) -> Running {
        let daemon = Daemon::builder(node.config())
            .start()
            .await
            .expect("gobyd starts");
        let addr = daemon.json_tcp_addr().expect("JSON on TCP");
        let (stop, stopped) = oneshot::channel::<()>();
        let running = tokio::spawn(daemon.run(async {
            let _ = stopped.await;
        }));
        let (read, write) = TcpStream::connect(addr).await.unwrap().into_split();
        let mut r = Running {
            lines: BufReader::new(read).lines(),
            held: Default::default(),
            write,
            stop,
            running,
        };
        r.request(&json!({"subscribe": ["forecast"]})).await;
        r
    }

    /// Writes `line`; returns its reply (events before it are held for
    /// [`next`](Self::next)).
    async fn request(&mut self, line: &Value) -> Value {
        self.write
            .write_all(format!("{line}\n").as_bytes())
            .await
            .unwrap();
        tokio::time::timeout(PATIENCE, async {
            loop {
                let line = self.lines.next_line().await.unwrap().expect("open");
                let v: Value = serde_json::from_str(&line).unwrap();
                if v.get("reply").is_some() {
                    return v;
                }
                self.held.push_back(v);
            }
        })
        .await
        .expect("a reply in time")
    }

    /// The next line `wanted` takes (held lines first; others skipped).
    async fn next(&mut self, wanted: impl Fn(&Value) -> bool) -> Value {
        while let Some(v) = self.held.pop_front() {
            if wanted(&v) {
                return v;
            }
        }
        tokio::time::timeout(PATIENCE, async {
            loop {
                let line = self.lines.next_line().await.unwrap().expect("open");
                let v: Value = serde_json::from_str(&line).unwrap();
                if wanted(&v) {
                    return v;
                }
            }
        })
        .await
        .expect("in time")
    }

    /// The next event of kind `kind`.
    async fn event(&mut self, kind: &str) -> Value {
        self.next(|v| v["event"] == kind).await
    }

    async fn stop(self) {
        let _ = self.stop.send(());
        self.running.await.unwrap().unwrap();
    }
}

/// The CTD samples of the summer yo-yo record (time, depth, temperature,
/// salinity), as `ctd` request samples.
fn yoyo() -> Vec<Value> {
    std::fs::read_to_string(data("ctd/summer-yoyo.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
            json!({"time": v[0], "depth": v[1], "temperature": v[2], "salinity": v[3]})
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_json_request_gives_snr_and_frame_errors_per_peer_and_a_recommended_depth() {
    let dir = scratch("forecast", "json");
    let mut d = Running::start(node(&dir, "forecast-json", &forecast_section(""))).await;
    let reply = d.request(&json!({"forecast": {}})).await;
    assert!(reply["forecast"].as_f64().is_some(), "{reply}");
    let f = d.event("forecast").await;
    assert_eq!(f["environment"], "configuration", "{f}");
    assert_eq!(f["own"], json!({"x": 3000.0, "y": 0.0, "depth": 6.0}));
    let peer = &f["peers"][0];
    assert_eq!(peer["node"], 2, "{f}");
    assert!((peer["range"].as_f64().unwrap() - 3000.0).abs() < 1e-6);
    let snr = peer["snr"].as_f64().expect("an SNR");
    assert!(snr > 0.0 && snr < 80.0, "{snr}");
    let rates: Vec<u64> = peer["rates"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["rate"].as_u64().unwrap())
        .collect();
    assert_eq!(rates, [0, 1, 3, 5]);
    let band = &f["band"];
    assert_eq!(band["peer"], 2);
    assert_eq!(band["rate"], 1);
    assert_eq!(band["depths"].as_array().unwrap().len(), 25, "{band}");
    let best = band["recommended"].as_f64().expect("a recommended depth");
    // The least TL of the band is where the forecast recommends.
    let tl: Vec<f64> = band["tl"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap_or(f64::INFINITY))
        .collect();
    let i = band["depths"]
        .as_array()
        .unwrap()
        .iter()
        .position(|d| d.as_f64() == Some(best))
        .unwrap();
    assert!(tl.iter().all(|t| *t >= tl[i]), "{best} m: {tl:?}");
    assert!(f.get("error").is_none(), "{f}");

    // A new position moves the forecast.
    let reply = d
        .request(&json!({"nav": {"x": 2000.0, "y": 0.0, "depth": 40.0}}))
        .await;
    assert_eq!(reply["nav"]["depth"], 40.0);
    d.request(&json!({"forecast": {}})).await;
    let f = d
        .next(|v| v["event"] == "forecast" && v["own"]["depth"] == 40.0)
        .await;
    assert!((f["peers"][0]["range"].as_f64().unwrap() - 2000.0).abs() < 1e-6);
    d.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ctd_samples_build_the_profile_and_bad_ones_are_refused_keeping_the_last_good() {
    let dir = scratch("forecast", "ctd");
    let section = forecast_section("ctd { bin: 2 window_seconds: 1800 latitude: 42.5 }");
    let mut d = Running::start(node(&dir, "forecast-ctd", &section)).await;
    let samples = yoyo();
    let reply = d.request(&json!({ "ctd": samples })).await;
    assert_eq!(reply["ctd"], samples.len(), "{reply}");
    let env = d.event("environment").await;
    assert_eq!(env["environment"], "ctd", "{env}");
    let profile: Vec<[f64; 2]> = serde_json::from_value(env["profile"].clone()).unwrap();
    assert_eq!(profile[0][0], 0.0);
    assert_eq!(profile.last().unwrap()[0], 111.0);
    // Warm over cold: faster above the thermocline than below it.
    let at = |z: f64| profile.iter().find(|p| p[0] >= z).unwrap()[1];
    assert!(at(5.0) - at(40.0) > 15.0, "{profile:?}");

    // A batch with one bad sample is refused whole, naming it; the profile
    // stays the last good one.
    let bad = json!({"ctd": [
        {"time": 3700.0, "depth": 10.0, "temperature": 22.0, "salinity": 38.0},
        {"time": 3705.0, "depth": 12.0, "temperature": 99.0, "salinity": 38.0},
    ]});
    let reply = d.request(&bad).await;
    let error = reply["error"].as_str().expect("refused");
    assert!(error.starts_with("ctd[1].temperature: 99"), "{error}");
    let refused = d.event("environment").await;
    assert!(refused["refused"]
        .as_str()
        .unwrap()
        .contains("ctd[1].temperature"));
    assert_eq!(refused["profile"], env["profile"]);
    // None of the batch is held: its good first sample neither.
    assert_eq!(refused["samples"], env["samples"], "{refused}");
    let below =
        json!({"ctd": {"time": 3700.0, "depth": 500.0, "temperature": 15.0, "salinity": 38.0}});
    let error = d.request(&below).await["error"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        error.starts_with("ctd[0].depth: 500 m is on or below the bottom"),
        "{error}"
    );

    // The forecast goes on in the last good environment (the one made at
    // the start, before the samples, is skipped).
    d.request(&json!({"forecast": {}})).await;
    let f = d
        .next(|v| v["event"] == "forecast" && v["environment"] != "configuration")
        .await;
    assert_eq!(f["environment"], "ctd", "{f}");
    assert!(f["samples"].as_u64().unwrap() > 300, "{f}");
    assert!(f["band"]["recommended"].as_f64().is_some(), "{f}");
    d.stop().await;
}

/// The error `--check` (and the start) gives for the `forecast` section
/// `section`.
fn refused(dir: &Path, section: &str) -> String {
    let config = node(dir, "forecast-check", section).config();
    gobyd::check::check(config).expect_err(section).to_string()
}

#[test]
fn check_refuses_a_bad_forecast_section_naming_the_field_or_the_file_and_line() {
    let dir = scratch("forecast", "check");
    let inline = |profile: &str, more: &str| {
        format!(r#"forecast {{ water {{ {profile} }} own {{ x: 100 depth: 10 }} {more} }}"#)
    };
    let two = "profile { depth: 0 speed: 1520 } profile { depth: 100 speed: 1500 }";
    let cases: Vec<(String, &str)> = vec![
        (
            inline("profile { depth: 0 speed: 1520 }", ""),
            "forecast.water.profile: a sound speed profile needs at least two points",
        ),
        (
            // The bottom given beside it does not make one point a profile.
            inline("profile { depth: 0 speed: 1520 }", "water_depth: 111"),
            "forecast.water.profile: a sound speed profile needs at least two points, this one has 1",
        ),
        (
            inline(
                "profile { depth: -5 speed: 1520 } profile { depth: 100 speed: 1500 }",
                "",
            ),
            "forecast.water.profile[0].depth",
        ),
        (
            inline(
                "profile { depth: 0 speed: nan } profile { depth: 100 speed: 1500 }",
                "",
            ),
            "forecast.water.profile[0].speed",
        ),
        (
            inline(two, "peer { modem_id: 2 position { x: 0 depth: 140 } }"),
            "forecast.peer[0].position.depth: 140 m is on or below the bottom (100 m there)",
        ),
        (
            format!(r#"forecast {{ water {{ {two} }} own {{ x: 100 depth: 120 }} }}"#),
            "forecast.own.depth: 120 m is on or below the bottom",
        ),
        (
            inline(two, "band_shallow: 20 band_deep: 10"),
            "forecast.band_deep",
        ),
        (inline(two, "rate: 2"), "forecast.rate"),
        (
            inline(
                two,
                "peer_position { protobuf_name: \"goby.example.NavigationReport\" }",
            ),
            "forecast.peer_position[0]: give depth_field",
        ),
        (
            inline(
                two,
                r#"peer_position { protobuf_name: "a.B" z_field: "z" lat_field: "lat" lon_field: "lon" }"#,
            ),
            "forecast.peer_position[0].lat_field: no origin",
        ),
    ];
    for (section, expected) in &cases {
        let err = refused(&dir, section);
        assert!(err.contains(expected), "{section}\n{err}");
    }
    let bathy = dir.join("bay.xyz");
    std::fs::write(&bathy, "0 0 100\n500 0 9O\n").unwrap();
    let section = inline(two, &format!(r#"bathymetry_file: "{}""#, bathy.display()));
    let err = refused(&dir, &section);
    assert!(
        err.contains(&format!(
            "forecast.bathymetry_file: {}:2: depth \"9O\" is not a number",
            bathy.display()
        )),
        "{err}"
    );
    let section = forecast_section("").replace("summer.env", "no-such.env");
    let err = refused(&dir, &section);
    assert!(
        err.contains("forecast.water.env") && err.contains("no-such.env"),
        "{err}"
    );
    // And a good one passes.
    gobyd::check::check(node(&dir, "forecast-check", &forecast_section("")).config())
        .expect("a good forecast section");
}

/// The forecast over MOOS through the DB at `port`: the navigation moves
/// this vehicle, a request asks for a forecast, and the variables an IvP
/// Helm behaviour takes arrive; a NaN CTD sample is refused by name.
async fn forecast_over_moos(port: u16, name: &str) {
    let dir = scratch("forecast", name);
    let section = forecast_section("ctd { } lat_origin: 42.5 lon_origin: 10.8");
    let node = node(&dir, name, &section).moos(port, r#"name: "gobyd_forecast""#);
    let d = Running::start(node).await;
    let deadline = tokio::time::Instant::now() + PATIENCE;
    let (client, mut mail) = loop {
        let config = ClientConfig::new("helm").with_address("127.0.0.1", port);
        match MoosClient::connect(config).await {
            Ok(connected) => break connected,
            Err(e) if tokio::time::Instant::now() > deadline => panic!("cannot connect: {e}"),
            Err(_) => tokio::time::sleep(Duration::from_millis(200)).await,
        }
    };
    for var in [
        "ACOMMS_DEPTH_UPDATES",
        "ACOMMS_FORECAST_PEERS",
        "ACOMMS_FORECAST",
    ] {
        client.register(var, Duration::ZERO).unwrap();
    }
    let mut updates = None;
    let mut peers = None;
    let mut refused = None;
    let mut tick = tokio::time::interval(Duration::from_millis(300));
    let limit = tokio::time::sleep(PATIENCE);
    tokio::pin!(limit);
    while updates.is_none() || peers.is_none() || refused.is_none() {
        tokio::select! {
            _ = tick.tick() => {
                // gobyd registers once connected: keep writing.
                client.notify_double("NAV_X", 2500.0).unwrap();
                client.notify_double("NAV_DEPTH", 10.0).unwrap();
                client.notify_string("GOBYD_FORECAST_REQUEST", "now").unwrap();
                client
                    .notify_string("GOBYD_CTD", "depth=5,temperature=nan,salinity=38")
                    .unwrap();
            }
            m = mail.recv() => {
                let m = m.expect("mail open");
                let MoosValue::String(s) = m.value else { continue };
                match m.key.as_str() {
                    "ACOMMS_FORECAST_PEERS" if s.contains("range=2500") => peers = Some(s),
                    "ACOMMS_DEPTH_UPDATES" if peers.is_some() => updates = Some(s),
                    "ACOMMS_FORECAST" if s.contains("refused") => refused = Some(s),
                    _ => {}
                }
            }
            () = &mut limit => {
                panic!("timed out: updates {updates:?}, peers {peers:?}, refused {refused:?}")
            }
        }
    }
    let updates = updates.unwrap();
    let depth: f64 = updates
        .strip_prefix("depth=")
        .and_then(|d| d.parse().ok())
        .unwrap_or_else(|| panic!("not depth=D: {updates}"));
    assert!((2.0..=100.0).contains(&depth), "{updates}");
    let peers = peers.unwrap();
    assert!(
        peers.starts_with("node=2,range=2500,snr=") && peers.contains(",fer="),
        "{peers}"
    );
    let refused: Value = serde_json::from_str(&refused.unwrap()).unwrap();
    assert_eq!(refused["event"], "environment");
    assert!(
        refused["refused"]
            .as_str()
            .unwrap()
            .starts_with("ctd[0].temperature"),
        "{refused}"
    );
    assert_eq!(refused["environment"], "configuration");

    // Latitude and longitude place the vehicle on the local grid: 2 km
    // north of the origin, 2 km from the buoy.
    let grid = gobyd::translator::local_grid::LocalGrid::new(42.5, 10.8).unwrap();
    let (lat, lon) = grid.to_geo(0.0, 2000.0).unwrap();
    let placed = tokio::time::timeout(PATIENCE, async {
        let mut tick = tokio::time::interval(Duration::from_millis(300));
        loop {
            tokio::select! {
                _ = tick.tick() => {
                    client.notify_double("NAV_LAT", lat).unwrap();
                    client.notify_double("NAV_LONG", lon).unwrap();
                    client.notify_string("GOBYD_FORECAST_REQUEST", "now").unwrap();
                }
                m = mail.recv() => {
                    let m = m.expect("mail open");
                    if let (true, MoosValue::String(s)) = (m.key == "ACOMMS_FORECAST_PEERS", m.value) {
                        if s.contains("range=2000,") {
                            return s;
                        }
                    }
                }
            }
        }
    })
    .await
    .expect("placed by latitude and longitude in time");
    assert!(placed.starts_with("node=2,range=2000,"), "{placed}");
    client.close().await;
    d.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_forecast_variables_arrive_through_the_minimal_db() {
    let db = moos::testing::MiniDb::start("127.0.0.1:0", "gobytest")
        .await
        .unwrap();
    forecast_over_moos(db.port(), "forecast-minidb").await;
    db.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "needs a real MOOSDB on PATH: cargo test -p gobyd --test forecast -- --ignored"]
async fn the_forecast_variables_arrive_through_a_real_moosdb() {
    let exe = moosdb_on_path()
        .expect("no MOOSDB on PATH: put the MOOS core's bin directory there to run this test");
    let dir = scratch("forecast", "moosdb-run");
    let db = RealMoosDb::start(&exe, &dir, "gobytest");
    forecast_over_moos(db.port, "forecast-moosdb").await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_forecast_is_retained_on_its_mqtt_topic_for_the_console() {
    let dir = scratch("forecast", "mqtt");
    let broker = Broker::start(
        &dir,
        "the_forecast_is_retained_on_its_mqtt_topic_for_the_console",
    );
    let node = node(&dir, "forecast-mqtt", &forecast_section("ctd { }")).mqtt(
        &broker.address(),
        "fleet",
        "",
    );
    let mut d = Running::start(node).await;
    let bad = json!({"ctd": {"time": 1.0, "depth": -2.0, "temperature": 15.0, "salinity": 38.0}});
    assert!(d.request(&bad).await["error"]
        .as_str()
        .unwrap()
        .starts_with("ctd[0].depth"));
    // Retained: a console subscribing later gets the last one.
    let watcher = Watcher::start(&broker.address(), "console", "fleet/#");
    let (forecast, environment) = tokio::task::block_in_place(|| {
        let f = watcher.wait_on("fleet/1/forecast", |v| {
            v["band"]["recommended"].as_f64().map(|_| v.clone())
        });
        let e = watcher.wait_on("fleet/1/environment", |v| Some(v.clone()));
        (f, e)
    });
    assert_eq!(forecast["event"], "forecast");
    assert_eq!(forecast["peers"][0]["node"], 2, "{forecast}");
    assert!(environment["refused"]
        .as_str()
        .unwrap()
        .starts_with("ctd[0].depth"));
    d.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_received_message_carrying_its_senders_position_places_the_peer() {
    let dir = scratch("forecast", "peer");
    let section = forecast_section(
        r#"peer_position { protobuf_name: "goby.example.NavigationReport" z_field: "z" }"#,
    );
    let node = node(&dir, "forecast-peer", &section).queue(
        Entry::new("goby.example.NavigationReport")
            .role("SOURCE_ID", "source")
            .role("DESTINATION_ID", "destination"),
    );
    let mut d = Running::start(node).await;
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs();
    // Node 3's report, addressed to this node (delivered at once, as a
    // received message is).
    let report = json!({"publish": "goby.example.NavigationReport", "msg": {
        "source": 3, "destination": 1, "time": now, "x": 1500.0, "y": 0.0, "z": -20.0,
    }});
    let reply = d.request(&report).await;
    assert_eq!(reply["delivered"], true, "{reply}");
    d.request(&json!({"forecast": {}})).await;
    let f = d
        .next(|v| {
            v["event"] == "forecast"
                && v["peers"]
                    .as_array()
                    .is_some_and(|p| p.iter().any(|p| p["node"] == 3))
        })
        .await;
    let peer = f["peers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["node"] == 3)
        .unwrap();
    assert_eq!(
        peer["position"],
        json!({"x": 1500.0, "y": 0.0, "depth": 20.0})
    );
    assert!(
        (peer["range"].as_f64().unwrap() - 1500.0).abs() < 1e-6,
        "{peer}"
    );
    assert!(peer["snr"].as_f64().is_some(), "{peer}");
    // The band is for the nearest peer: node 3 now.
    assert_eq!(f["band"]["peer"], 3, "{f}");
    d.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_forecast_section_the_requests_are_answered_with_why() {
    let dir = scratch("forecast", "none");
    let mut d = Running::start(node(&dir, "forecast-none", "")).await;
    for line in [
        json!({"forecast": {}}),
        json!({"nav": {"x": 1.0, "y": 2.0, "depth": 3.0}}),
        json!({"ctd": []}),
    ] {
        let reply = d.request(&line).await;
        assert_eq!(
            reply["error"], "no link forecast: the configuration has no forecast section",
            "{line}"
        );
    }
    d.stop().await;
}
