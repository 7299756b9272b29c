//! Fleet scale over MQTT: N gateways (in-process gobyd daemons, each on its
//! own acoustic simulator, each bridged to one Mosquitto broker on
//! loopback) and C consoles.
//!
//! A console publishes 200 Command messages per gateway (at least 10 000)
//! spread over the gateways' `tx` topics (QoS 1). Each gateway parses one,
//! queues it, syncs its journal, acknowledges it to the broker and
//! publishes `accepted` and the new queue size (a retained state: sizes
//! still waiting for the broker give way to the newest); every console is
//! subscribed to those. Figures: messages per second end to end (console
//! publish → journaled → `accepted` back at the consoles), publications per
//! second delivered by the broker to the consoles (fan-out), the share of
//! one processor the broker used meanwhile and the share this process
//! (gateways, consoles, commander) used, and the machine's load average.
//!
//! `cargo bench -p gobyd --bench mqtt_scale [-- N...]` (default N = 1 10
//! 50) prints one JSON object per N. Needs Mosquitto (`.ci/mosquitto.sh`);
//! says so and exits without it. Journals live under `target/`. The
//! broker's settings beyond its listener and persistence are
//! `max_queued_messages 0`, or what `MQTT_SCALE_BROKER` holds (e.g.
//! `max_queued_messages 0` and `max_inflight_messages 100` on two lines).

#[path = "../tests/support/broker.rs"]
mod broker;

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use gobyd::{config, daemon::Daemon};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use serde_json::json;

/// Messages per gateway per run (at least [`MIN_TOTAL`] in all).
const PER_GATEWAY: usize = 200;
/// Fewest messages in a run.
const MIN_TOTAL: usize = 10_000;
/// Consoles watching.
const CONSOLES: usize = 4;

fn gateway_config(id: usize, broker: &str, dir: &std::path::Path) -> String {
    format!(
        r#"
modem_id: {id}
driver {{
  driver_type: DRIVER_ACOUSTIC_SIMULATOR
  simulator {{ node {{ modem_id: {id} }} channel: "gateway{id}" }}
}}
queue {{
  message_entry {{
    protobuf_name: "goby.example.Command"
    ack: true ttl: 1800 max_queue: 100000
    role {{ type: DESTINATION_ID field: "destination" }}
  }}
}}
json {{ tcp_bind: "" }}
mqtt {{ broker: "{broker}" topic_prefix: "bench" buffer: 100000 }}
data_dir: "{}"
log {{ raw_log: false }}
"#,
        dir.join(format!("gateway{id}")).display()
    )
}

fn console(broker: &str, name: &str) -> (AsyncClient, rumqttc::EventLoop) {
    let (host, port) = broker.split_once(':').unwrap();
    let mut options = MqttOptions::new(name, host, port.parse().unwrap());
    options.set_keep_alive(Duration::from_secs(30));
    options.set_inflight(1000);
    AsyncClient::new(options, 10_000)
}

/// Processor seconds this process (gateways, consoles, commander) used so
/// far, from `/proc/self/stat`.
fn own_cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rfind(')').map(|i| &stat[i + 2..]).unwrap_or("");
    let fields: Vec<f64> = after
        .split_whitespace()
        .map(|f| f.parse().unwrap_or(f64::NAN))
        .collect();
    match (fields.get(11), fields.get(12)) {
        (Some(u), Some(s)) => (u + s) / 100.0,
        _ => f64::NAN,
    }
}

/// The machine's load average over the last minute.
fn load_average() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next()?.parse().ok())
        .unwrap_or(f64::NAN)
}

async fn run(n: usize, broker: &broker::Broker, dir: &std::path::Path) -> serde_json::Value {
    let broker_cpu = || broker.cpu_seconds().unwrap_or(f64::NAN);
    let address = broker.address();
    let broker = address.as_str();
    let mut daemons = Vec::new();
    let mut stops = Vec::new();
    for id in 1..=n {
        let text = gateway_config(id, broker, dir);
        let config = config::parse(&text, "bench").unwrap();
        let daemon = Daemon::builder(config)
            .start()
            .await
            .expect("gateway starts");
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        stops.push(stop);
        daemons.push(tokio::spawn(daemon.run(async {
            let _ = stopped.await;
        })));
    }
    // Consoles count what reaches them.
    let accepted = Arc::new(AtomicU64::new(0));
    let delivered = Arc::new(AtomicU64::new(0));
    let mut console_tasks = Vec::new();
    for c in 0..CONSOLES {
        let (client, mut eventloop) = console(broker, &format!("console{c}-{n}"));
        client
            .subscribe("bench/+/accepted", QoS::AtLeastOnce)
            .await
            .unwrap();
        client
            .subscribe("bench/+/queue/+", QoS::AtLeastOnce)
            .await
            .unwrap();
        let (accepted, delivered) = (accepted.clone(), delivered.clone());
        console_tasks.push(tokio::spawn(async move {
            let _client = client;
            loop {
                match eventloop.poll().await {
                    Ok(Event::Incoming(Packet::Publish(p))) => {
                        delivered.fetch_add(1, Ordering::Relaxed);
                        if c == 0 && p.topic.ends_with("/accepted") {
                            accepted.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                    Ok(_) => {}
                    Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
                }
            }
        }));
    }
    // Every gateway online (its retained status seen), consoles subscribed.
    tokio::time::sleep(Duration::from_secs(2)).await;
    let total = (n * PER_GATEWAY).max(MIN_TOTAL);
    let (publisher, mut eventloop) = console(broker, &format!("commander-{n}"));
    let pumping = tokio::spawn(async move {
        loop {
            if eventloop.poll().await.is_err() {
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    });
    let delivered_before = delivered.load(Ordering::Relaxed);
    let cpu_before = broker_cpu();
    let own_before = own_cpu_seconds();
    let start = Instant::now();
    for i in 0..total {
        let gateway = i % n + 1;
        let payload = json!({"destination": 0, "action": "GOTO", "note": format!("m{i}")});
        publisher
            .publish(
                format!("bench/{gateway}/tx/goby.example.Command"),
                QoS::AtLeastOnce,
                false,
                payload.to_string(),
            )
            .await
            .unwrap();
    }
    // Until every message is back, or nothing more came for 10 s.
    let (mut last, mut last_change) = (0, Instant::now());
    loop {
        let now_accepted = accepted.load(Ordering::Relaxed);
        if now_accepted as usize >= total || last_change.elapsed() > Duration::from_secs(10) {
            break;
        }
        if now_accepted != last {
            (last, last_change) = (now_accepted, Instant::now());
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    // An incomplete run is timed to its last progress.
    let complete = accepted.load(Ordering::Relaxed) as usize >= total;
    let end = if complete {
        Instant::now()
    } else {
        last_change
    };
    let seconds = end.duration_since(start).as_secs_f64().max(1e-3);
    let broker_busy = (broker_cpu() - cpu_before) / seconds;
    let own_busy = (own_cpu_seconds() - own_before) / seconds;
    let got = accepted.load(Ordering::Relaxed);
    let fan_out = delivered.load(Ordering::Relaxed) - delivered_before;
    pumping.abort();
    for task in console_tasks {
        task.abort();
    }
    for stop in stops {
        let _ = stop.send(());
    }
    for daemon in daemons {
        let _ = daemon.await;
    }
    json!({
        "gateways": n,
        "consoles": CONSOLES,
        "messages": total,
        "accepted": got,
        "seconds": (seconds * 1000.0).round() / 1000.0,
        "end_to_end_per_second": (got as f64 / seconds).round(),
        "console_deliveries": fan_out,
        "fan_out_per_second": (fan_out as f64 / seconds).round(),
        "broker_cpu_share": (broker_busy * 100.0).round() / 100.0,
        "gateways_and_clients_cpu_share": (own_busy * 100.0).round() / 100.0,
        "load_average": load_average(),
    })
}

fn main() {
    let counts: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let counts = if counts.is_empty() {
        vec![1, 10, 50]
    } else {
        counts
    };
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../target/mqtt-scale")
        .join(std::process::id().to_string());
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // The broker may queue any number of messages for a console that lags
    // (its default drops beyond 1000).
    let settings =
        std::env::var("MQTT_SCALE_BROKER").unwrap_or_else(|_| "max_queued_messages 0".into());
    let Some(broker) = broker::Broker::try_start_with(&dir, &settings) else {
        eprintln!(
            "mqtt_scale: nothing measured, Mosquitto is not installed (bash .ci/mosquitto.sh)"
        );
        return;
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap();
    for n in counts {
        let figures = runtime.block_on(run(n, &broker, &dir.join(n.to_string())));
        println!("{figures}");
    }
    drop(broker);
    let _ = std::fs::remove_dir_all(&dir);
}
