//! A UDP relay between two nodes on 127.0.0.1 that the test can silence:
//! the acoustic channel between two `gobyd` processes (the simulator's
//! datagrams pass through it) going dead and coming back.

#![allow(dead_code)]

use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// The relay: node 1 sends to [`Relay::to_node`]`(2)`, node 2 to
/// [`Relay::to_node`]`(1)`; each datagram goes on to the other node's
/// port, unless the relay is silent.
pub struct Relay {
    ports: [u16; 2],
    silent: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    passed: Arc<AtomicU64>,
    dropped: Arc<AtomicU64>,
    threads: Vec<JoinHandle<()>>,
}

impl Relay {
    /// Between node 1 receiving on `nodes[0]` and node 2 on `nodes[1]`.
    pub fn start(nodes: [u16; 2]) -> Relay {
        let silent = Arc::new(AtomicBool::new(false));
        let stop = Arc::new(AtomicBool::new(false));
        let passed = Arc::new(AtomicU64::new(0));
        let dropped = Arc::new(AtomicU64::new(0));
        let mut ports = [0; 2];
        let mut threads = Vec::new();
        for (i, to) in nodes.iter().enumerate() {
            let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
            socket
                .set_read_timeout(Some(Duration::from_millis(50)))
                .unwrap();
            ports[i] = socket.local_addr().unwrap().port();
            let to = format!("127.0.0.1:{to}");
            let (silent, stop, passed, dropped) = (
                silent.clone(),
                stop.clone(),
                passed.clone(),
                dropped.clone(),
            );
            threads.push(std::thread::spawn(move || {
                let mut buf = vec![0u8; 65536];
                while !stop.load(Ordering::Relaxed) {
                    let Ok((n, _)) = socket.recv_from(&mut buf) else {
                        continue;
                    };
                    if silent.load(Ordering::Relaxed) {
                        dropped.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    if socket.send_to(&buf[..n], &to).is_ok() {
                        passed.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }));
        }
        Relay {
            ports,
            silent,
            stop,
            passed,
            dropped,
            threads,
        }
    }

    /// The port to send to for node `id` (1 or 2) to receive.
    pub fn to_node(&self, id: i32) -> u16 {
        self.ports[(id - 1) as usize]
    }

    /// Drops every datagram from now on (`true`), or passes them again.
    pub fn silence(&self, on: bool) {
        self.silent.store(on, Ordering::Relaxed);
    }

    /// Datagrams passed on and dropped so far.
    pub fn counts(&self) -> (u64, u64) {
        (
            self.passed.load(Ordering::Relaxed),
            self.dropped.load(Ordering::Relaxed),
        )
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}
