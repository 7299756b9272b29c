//! gobyd figures: messages per second accepted on the JSON interface (one
//! pipelining client; four concurrent clients, each waiting for its reply;
//! four concurrent clients pipelining), the latency from a client's line to
//! the frame handed to the driver (alone, under the four clients' full load
//! and under a steady 1 000 messages a second), and the daemon's resident
//! memory at idle and under load.
//!
//! `cargo bench -p gobyd --bench gobyd` prints one JSON object. The
//! journal lives under `target/` (the disk the project is built on): every
//! accepted message is synced to it before the client hears "accepted".

use std::io::{BufRead, BufReader, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use gobyd::{config, daemon::Daemon};
use modemdriver::{Driver, DriverCommand};
use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::sync::{mpsc, oneshot};

const ACCEPT_COUNT: usize = 5000;
const LATENCY_COUNT: usize = 300;
/// Concurrent clients of the load runs.
const LOAD_CLIENTS: usize = 4;
/// Messages each load client publishes, one at a time.
const LOAD_PER_CLIENT: usize = 500;
/// Messages each load client publishes pipelined (all its lines written at
/// once, the replies read as they come).
const PIPELINED_PER_CLIENT: usize = 2500;
/// Messages a second of the steady load (all clients together).
const STEADY_RATE: u32 = 1000;
/// Length of the steady load.
const STEADY_TIME: Duration = Duration::from_secs(5);
/// Time between two probes of the steady load.
const PROBE_EVERY: Duration = Duration::from_millis(10);
/// Destination of the load's messages; probes go to another node, and the
/// driver asks only for frames to that one, so the load piles up in its
/// queue (journaled) while each probe leaves at once.
const LOAD_DEST: i32 = 2;
const PROBE_DEST: i32 = 3;
/// Time between two requests for data of a probe whose message was not in
/// the frame yet.
const RETRY: Duration = Duration::from_micros(50);

/// A driver that, told to transmit, asks for data once and reports the
/// frame it got (empty or not) with the instant it came back. The probe
/// asks again every [`RETRY`] until its message is in the frame: a slot
/// starting every 50 µs, without a task spinning on the processors the
/// daemon runs on.
fn bench_driver(frames: mpsc::UnboundedSender<(Instant, Vec<Vec<u8>>)>) -> Driver {
    Driver::spawn("bench", move |mut ctx| async move {
        while let Some(command) = ctx.commands.recv().await {
            match command {
                DriverCommand::Initiate(template) => {
                    let filled = ctx
                        .events
                        .request_data(template, Duration::from_secs(1))
                        .await;
                    let _ = frames.send((Instant::now(), filled.frame));
                }
                DriverCommand::Stop(done) => {
                    let _ = done.send(());
                    break;
                }
                DriverCommand::Specific(_) | DriverCommand::Acknowledge(_) => {}
            }
        }
    })
}

fn percentile(sorted: &[Duration], p: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i].as_secs_f64() * 1e6
}

/// Now, whole seconds since the UNIX epoch: the time the messages carry
/// (the door refuses a time the receiver would restore on another day).
fn now_seconds() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs()
}

fn publish_line(i: usize) -> String {
    let t = now_seconds();
    let x = i % 10_000;
    format!(
        "{{\"publish\": \"goby.example.NavigationReport\", \"msg\": {{\"source\": 1, \"destination\": 0, \"time\": {t}, \"x\": {x}, \"y\": -3.5, \"z\": -10}}}}\n"
    )
}

fn probe_line(i: usize) -> String {
    format!(
        "{{\"publish\": \"goby.example.Command\", \"msg\": {{\"destination\": {PROBE_DEST}, \"action\": \"GOTO\", \"note\": \"p{i}\"}}}}\n"
    )
}

fn load_line(client: usize, i: usize) -> String {
    let t = now_seconds();
    let x = i % 10_000;
    format!(
        "{{\"publish\": \"goby.example.NavigationReport\", \"msg\": {{\"source\": 1, \"destination\": {LOAD_DEST}, \"time\": {t}, \"x\": {x}, \"y\": {client}, \"z\": -10}}}}\n"
    )
}

/// A connected client: its writer and its reader.
fn client(addr: std::net::SocketAddr) -> (TcpStream, BufReader<TcpStream>) {
    let stream = TcpStream::connect(addr).unwrap();
    stream.set_nodelay(true).unwrap();
    (stream.try_clone().unwrap(), BufReader::new(stream))
}

/// Reads `n` replies, each of them `accepted`.
fn read_accepted(reader: &mut BufReader<TcpStream>, n: usize) {
    let mut line = String::new();
    for _ in 0..n {
        line.clear();
        reader.read_line(&mut line).unwrap();
        assert!(line.contains("\"accepted\""), "{line}");
    }
}

/// One probe: the probe line written, then data asked for every
/// [`RETRY`] until a frame holds it; the time from the line to that frame,
/// and to its `accepted` reply.
fn probe(
    runtime: &tokio::runtime::Runtime,
    handle: &modemdriver::DriverHandle,
    frames_rx: &mut mpsc::UnboundedReceiver<(Instant, Vec<Vec<u8>>)>,
    writer: &mut TcpStream,
    reader: &mut BufReader<TcpStream>,
    i: usize,
) -> (Duration, Duration) {
    let sent = Instant::now();
    writer.write_all(probe_line(i).as_bytes()).unwrap();
    let to_frame = loop {
        handle
            .initiate_transmission(ModemTransmission {
                dest: Some(PROBE_DEST),
                max_frame_bytes: Some(32),
                max_num_frames: Some(1),
                ..Default::default()
            })
            .unwrap();
        let (at, frames) = runtime.block_on(frames_rx.recv()).unwrap();
        if frames.first().is_some_and(|f| !f.is_empty()) {
            break at - sent;
        }
        std::thread::sleep(RETRY);
    };
    read_accepted(reader, 1);
    (to_frame, sent.elapsed())
}

fn resident_kib(pid: u32) -> Option<u64> {
    status_kib(pid, "VmRSS:")
}

/// A memory figure (kB) of `/proc/PID/status`.
fn status_kib(pid: u32, field: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find(|l| l.starts_with(field))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

fn idle_memory(data_dir: &std::path::Path) -> Option<u64> {
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(["--json-tcp", "127.0.0.1:0", "--data-dir"])
        .arg(data_dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .ok()?;
    std::thread::sleep(Duration::from_secs(3));
    let rss = resident_kib(child.id());
    let _ = child.kill();
    let _ = child.wait();
    rss
}

fn main() {
    let data_root = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../target/gobyd-bench")
        .join(std::process::id().to_string());
    let _ = std::fs::remove_dir_all(&data_root);
    std::fs::create_dir_all(&data_root).unwrap();

    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let (frames_tx, mut frames_rx) = mpsc::unbounded_channel();
    let text = format!(
        "modem_id: 1\nmac {{ type: MAC_NONE }}\njson {{ tcp_bind: \"127.0.0.1:0\" }}\n\
         queue {{ message_entry {{ protobuf_name: \"goby.example.NavigationReport\" ack: false max_queue: 100000 \
         role {{ type: DESTINATION_ID field: \"destination\" }} }} \
         message_entry {{ protobuf_name: \"goby.example.Command\" ack: false max_queue: 100000 \
         role {{ type: DESTINATION_ID field: \"destination\" }} }} }}\n\
         data_dir: \"{}\"\nlog {{ raw_log: false }}\n",
        data_root.join("daemon").display()
    );
    let (addr, handle, stop, running) = runtime.block_on(async {
        let driver = bench_driver(frames_tx);
        let handle = driver.handle();
        let daemon = Daemon::builder(config::parse(&text, "bench").unwrap())
            .driver(driver)
            .start()
            .await
            .expect("gobyd starts");
        let addr = daemon.json_tcp_addr().expect("JSON interface");
        let (stop, stopped) = oneshot::channel::<()>();
        let running = tokio::spawn(daemon.run(async {
            let _ = stopped.await;
        }));
        (addr, handle, stop, running)
    });

    let stream = TcpStream::connect(addr).unwrap();
    stream.set_nodelay(true).unwrap();
    let mut writer = stream.try_clone().unwrap();
    let mut reader = BufReader::new(stream);
    let mut line = String::new();

    // Throughput: every line written at once, then every reply read.
    let lines: String = (0..ACCEPT_COUNT).map(publish_line).collect();
    let start = Instant::now();
    std::thread::scope(|scope| {
        let mut writer = writer.try_clone().unwrap();
        scope.spawn(move || writer.write_all(lines.as_bytes()).unwrap());
        read_accepted(&mut reader, ACCEPT_COUNT);
    });
    let accept_rate = ACCEPT_COUNT as f64 / start.elapsed().as_secs_f64();

    // Empty the queue: one transmission of many frames.
    handle
        .initiate_transmission(ModemTransmission {
            max_frame_bytes: Some(1 << 20),
            max_num_frames: Some(1),
            ..Default::default()
        })
        .unwrap();
    runtime.block_on(frames_rx.recv()).unwrap();

    // Latency: the driver is asking for data when the line is written; the
    // frame holding the message comes back, then the "accepted" reply
    // (after the journal sync).
    let mut accept_latency = Vec::with_capacity(LATENCY_COUNT);
    let mut frame_latency = Vec::with_capacity(LATENCY_COUNT);
    for i in 0..LATENCY_COUNT {
        handle
            .initiate_transmission(ModemTransmission {
                max_frame_bytes: Some(32),
                max_num_frames: Some(1),
                ..Default::default()
            })
            .unwrap();
        let sent = Instant::now();
        writer.write_all(publish_line(i).as_bytes()).unwrap();
        let (at, frames) = runtime.block_on(frames_rx.recv()).unwrap();
        assert!(frames.first().is_some_and(|f| !f.is_empty()), "no frame");
        frame_latency.push(at - sent);
        line.clear();
        reader.read_line(&mut line).unwrap();
        assert!(line.contains("\"accepted\""), "{line}");
        accept_latency.push(sent.elapsed());
    }
    accept_latency.sort();
    frame_latency.sort();

    // Load: four clients publish at once, each waiting for its reply (its
    // message on disk) before the next; meanwhile probes measure the line
    // to frame latency on this connection.
    let started = std::sync::Barrier::new(LOAD_CLIENTS + 1);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let mut load_frame_latency = Vec::new();
    let mut load_accept_latency = Vec::new();
    let load_elapsed = std::thread::scope(|scope| {
        let clients: Vec<_> = (0..LOAD_CLIENTS)
            .map(|c| {
                let started = &started;
                let done = &done;
                scope.spawn(move || {
                    let (mut writer, mut reader) = client(addr);
                    started.wait();
                    for i in 0..LOAD_PER_CLIENT {
                        writer.write_all(load_line(c, i).as_bytes()).unwrap();
                        read_accepted(&mut reader, 1);
                    }
                    done.fetch_add(1, Ordering::SeqCst);
                })
            })
            .collect();
        started.wait();
        let start = Instant::now();
        let mut i = 0;
        while done.load(Ordering::SeqCst) < LOAD_CLIENTS {
            let (to_frame, to_reply) = probe(
                &runtime,
                &handle,
                &mut frames_rx,
                &mut writer,
                &mut reader,
                i,
            );
            load_frame_latency.push(to_frame);
            load_accept_latency.push(to_reply);
            i += 1;
        }
        for c in clients {
            c.join().unwrap();
        }
        start.elapsed()
    });
    let load_rate = (LOAD_CLIENTS * LOAD_PER_CLIENT) as f64 / load_elapsed.as_secs_f64();
    load_frame_latency.sort();
    load_accept_latency.sort();
    // The daemon runs in this process: its peak resident memory, clients
    // and the queued load included.
    let load_peak_kib = status_kib(std::process::id(), "VmHWM:");

    // Pipelined load: four clients write all their lines at once and read
    // the replies as they come.
    let started = std::sync::Barrier::new(LOAD_CLIENTS + 1);
    let pipelined_elapsed = std::thread::scope(|scope| {
        let clients: Vec<_> = (0..LOAD_CLIENTS)
            .map(|c| {
                let started = &started;
                scope.spawn(move || {
                    let (mut writer, mut reader) = client(addr);
                    let lines: String =
                        (0..PIPELINED_PER_CLIENT).map(|i| load_line(c, i)).collect();
                    started.wait();
                    std::thread::scope(|inner| {
                        inner.spawn(|| writer.write_all(lines.as_bytes()).unwrap());
                        read_accepted(&mut reader, PIPELINED_PER_CLIENT);
                    });
                })
            })
            .collect();
        started.wait();
        let start = Instant::now();
        for c in clients {
            c.join().unwrap();
        }
        start.elapsed()
    });
    let pipelined_rate =
        (LOAD_CLIENTS * PIPELINED_PER_CLIENT) as f64 / pipelined_elapsed.as_secs_f64();

    // Steady load: the four clients publish STEADY_RATE messages a second
    // between them, evenly spaced, without waiting for replies (read as
    // they come); probes every PROBE_EVERY measure line to frame.
    let per_client = Duration::from_secs(1) * LOAD_CLIENTS as u32 / STEADY_RATE;
    let steady_count = (STEADY_TIME.as_secs_f64() / per_client.as_secs_f64()) as usize;
    let steady_done = std::sync::atomic::AtomicUsize::new(0);
    let mut steady_frame_latency = Vec::new();
    let mut steady_accept_latency = Vec::new();
    let steady_elapsed = std::thread::scope(|scope| {
        let start = Instant::now();
        for c in 0..LOAD_CLIENTS {
            let steady_done = &steady_done;
            scope.spawn(move || {
                let (mut writer, mut reader) = client(addr);
                let offset = per_client * c as u32 / LOAD_CLIENTS as u32;
                std::thread::scope(|inner| {
                    inner.spawn(move || {
                        let mut next = start + offset;
                        for i in 0..steady_count {
                            if let Some(wait) = next.checked_duration_since(Instant::now()) {
                                std::thread::sleep(wait);
                            }
                            writer.write_all(load_line(c, i).as_bytes()).unwrap();
                            next += per_client;
                        }
                    });
                    read_accepted(&mut reader, steady_count);
                });
                steady_done.fetch_add(1, Ordering::SeqCst);
            });
        }
        let mut next = Instant::now();
        let mut i = 0;
        while steady_done.load(Ordering::SeqCst) < LOAD_CLIENTS {
            if let Some(wait) = next.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            let (to_frame, to_reply) = probe(
                &runtime,
                &handle,
                &mut frames_rx,
                &mut writer,
                &mut reader,
                LATENCY_COUNT + i,
            );
            steady_frame_latency.push(to_frame);
            steady_accept_latency.push(to_reply);
            i += 1;
            next += PROBE_EVERY;
        }
        start.elapsed()
    });
    let steady_rate = (LOAD_CLIENTS * steady_count) as f64 / steady_elapsed.as_secs_f64();
    steady_frame_latency.sort();
    steady_accept_latency.sort();

    let _ = stop.send(());
    runtime.block_on(running).unwrap().unwrap();
    let rss = idle_memory(&data_root.join("idle"));
    let _ = std::fs::remove_dir_all(&data_root);

    let report = serde_json::json!({
        "accepted_per_second": accept_rate.round(),
        "accept_latency_us": {
            "p50": percentile(&accept_latency, 0.5).round(),
            "p99": percentile(&accept_latency, 0.99).round(),
        },
        "line_to_frame_us": {
            "p50": percentile(&frame_latency, 0.5).round(),
            "p99": percentile(&frame_latency, 0.99).round(),
        },
        "idle_rss_mib": rss.map(|kib| (kib as f64 / 1024.0 * 10.0).round() / 10.0),
        "load": {
            "clients": LOAD_CLIENTS,
            "accepted_per_second": load_rate.round(),
            "probes": load_frame_latency.len(),
            "line_to_frame_us": {
                "p50": percentile(&load_frame_latency, 0.5).round(),
                "p99": percentile(&load_frame_latency, 0.99).round(),
            },
            "accept_latency_us": {
                "p50": percentile(&load_accept_latency, 0.5).round(),
                "p99": percentile(&load_accept_latency, 0.99).round(),
            },
            "peak_rss_mib": load_peak_kib.map(|kib| (kib as f64 / 1024.0 * 10.0).round() / 10.0),
        },
        "pipelined_load": {
            "clients": LOAD_CLIENTS,
            "messages": LOAD_CLIENTS * PIPELINED_PER_CLIENT,
            "accepted_per_second": pipelined_rate.round(),
        },
        "steady_load": {
            "clients": LOAD_CLIENTS,
            "messages_per_second": steady_rate.round(),
            "probes": steady_frame_latency.len(),
            "line_to_frame_us": {
                "p50": percentile(&steady_frame_latency, 0.5).round(),
                "p99": percentile(&steady_frame_latency, 0.99).round(),
            },
            "accept_latency_us": {
                "p50": percentile(&steady_accept_latency, 0.5).round(),
                "p99": percentile(&steady_accept_latency, 0.99).round(),
            },
        },
    });
    println!("{report}");
}
