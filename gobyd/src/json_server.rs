//! The JSON autonomy interface over TCP (one connection per client, one line
//! per request or event) and UDP (one datagram per line; a peer receives
//! events once it has sent any datagram).
//!
//! Connections parse their lines themselves and hand messages to publish to
//! the daemon's core through a channel, with a one-shot channel for the
//! reply line; events come back through a broadcast channel and each client
//! keeps those it subscribed to. A malformed line gets an `error` line back;
//! the connection and the daemon stay up.

use std::collections::{HashMap, HashSet};
use std::net::SocketAddr;
use std::sync::Arc;

use dccl::Codec;
use prost_reflect::DynamicMessage;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::{broadcast, mpsc, oneshot};
use tokio::task::JoinSet;

use super::json_protocol::{error_line, parse_request, Request, Topic};

/// A message a client wants sent, with where to send the reply line.
#[derive(Debug)]
pub struct Publish {
    /// The message.
    pub message: DynamicMessage,
    /// Receives the `accepted` or `error` line.
    pub reply: oneshot::Sender<String>,
}

/// A queue event as clients see it.
#[derive(Debug)]
pub struct ClientEvent {
    /// Its topic (`None`: for every client).
    pub topic: Option<Topic>,
    /// Its JSON line.
    pub line: String,
    /// The event itself (for interfaces that format it otherwise).
    pub event: queue::QueueEvent,
}

/// A shared [`ClientEvent`].
pub type EventLine = Arc<ClientEvent>;

/// Longest request line accepted, bytes.
const MAX_LINE: usize = 1024 * 1024;

/// What the connections share.
#[derive(Debug, Clone)]
pub struct JsonInterface {
    /// The codec: clients may publish the types loaded in it.
    pub codec: Arc<Codec>,
    /// Where publish requests go.
    pub publish: mpsc::Sender<Publish>,
    /// Where event lines come from.
    pub events: broadcast::Sender<EventLine>,
}

impl JsonInterface {
    /// Handles one request line: the reply line to send now, if any
    /// (`None` after a subscription, which has no reply).
    async fn handle_line(&self, line: &str, topics: &mut HashSet<Topic>) -> Option<String> {
        match parse_request(line, &self.codec) {
            Err(e) => Some(error_line(&e)),
            Ok(Request::Subscribe(t)) => {
                topics.extend(t);
                None
            }
            Ok(Request::Publish(message)) => {
                let (reply, answer) = oneshot::channel();
                if self.publish.send(Publish { message, reply }).await.is_err() {
                    return Some(error_line("the daemon is shutting down"));
                }
                Some(
                    answer
                        .await
                        .unwrap_or_else(|_| error_line("the daemon is shutting down")),
                )
            }
        }
    }

    /// Accepts TCP clients until the task is dropped.
    pub async fn serve_tcp(self, listener: TcpListener) {
        let mut connections = JoinSet::new();
        loop {
            tokio::select! {
                accepted = listener.accept() => match accepted {
                    Ok((stream, peer)) => {
                        tracing::info!(%peer, "JSON client connected");
                        connections.spawn(self.clone().serve_connection(stream, peer));
                    }
                    Err(e) => tracing::warn!("JSON interface: accept failed: {e}"),
                },
                Some(_) = connections.join_next(), if !connections.is_empty() => {}
            }
        }
    }

    async fn serve_connection(self, stream: TcpStream, peer: SocketAddr) {
        let (read, mut write) = stream.into_split();
        let mut lines = BufReader::new(read);
        let mut events = self.events.subscribe();
        let mut topics = HashSet::new();
        let mut buf = Vec::new();
        loop {
            let out = tokio::select! {
                read = lines.read_until(b'\n', &mut buf) => match read {
                    Ok(0) => break,
                    Ok(_) if buf.len() > MAX_LINE => {
                        buf.clear();
                        Some(error_line("line too long"))
                    }
                    Ok(_) => {
                        let text = String::from_utf8_lossy(&buf).trim().to_string();
                        buf.clear();
                        if text.is_empty() {
                            None
                        } else {
                            self.handle_line(&text, &mut topics).await
                        }
                    }
                    Err(e) => {
                        tracing::info!(%peer, "JSON client read failed: {e}");
                        break;
                    }
                },
                event = events.recv() => match event {
                    Ok(event) => wanted(&event, &topics).then(|| event.line.clone()),
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        Some(error_line(&format!("{n} events were lost: the client reads too slowly")))
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                },
            };
            if let Some(mut line) = out {
                line.push('\n');
                if write.write_all(line.as_bytes()).await.is_err() {
                    break;
                }
            }
        }
        tracing::info!(%peer, "JSON client disconnected");
    }

    /// Serves UDP peers until the task is dropped.
    pub async fn serve_udp(self, socket: UdpSocket) {
        let mut events = self.events.subscribe();
        let mut peers: HashMap<SocketAddr, HashSet<Topic>> = HashMap::new();
        let mut buf = vec![0u8; 65_536];
        loop {
            tokio::select! {
                got = socket.recv_from(&mut buf) => {
                    let Ok((n, peer)) = got else { continue };
                    let text = String::from_utf8_lossy(&buf[..n]).to_string();
                    let topics = peers.entry(peer).or_default();
                    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
                        if let Some(reply) = self.handle_line(line, topics).await {
                            let _ = socket.send_to(reply.as_bytes(), peer).await;
                        }
                    }
                }
                event = events.recv() => match event {
                    Ok(event) => {
                        for (peer, topics) in &peers {
                            if wanted(&event, topics) {
                                let _ = socket.send_to(event.line.as_bytes(), peer).await;
                            }
                        }
                    }
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        tracing::warn!("JSON UDP interface lost {n} events");
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                },
            }
        }
    }
}

fn wanted(event: &EventLine, topics: &HashSet<Topic>) -> bool {
    match event.topic {
        None => true,
        Some(topic) => topics.contains(&topic),
    }
}
