//! The JSON autonomy interface over TCP (one connection per client, one line
//! per request, reply or event) and UDP (one line per datagram sent, a
//! datagram received may hold several request lines; a peer receives events
//! once it has sent any datagram). Replies go out in request order on both.
//!
//! Connections parse their lines themselves and hand messages to publish to
//! the daemon's core through a channel, with a one-shot channel for the
//! core's typed reply, rendered here; the core's typed events come back
//! through a broadcast channel, each client keeps those it subscribed to
//! and renders their lines ([`lines`]). Every request line gets exactly
//! one reply, numbered; a malformed line gets an `error` reply; the
//! connection and the daemon stay up.
//!
//! Resources are bounded: a line is cut off at [`MAX_LINE`] bytes as it
//! arrives (the rest of it is skipped), the line buffer shrinks back after a
//! long line, the accept loop backs off while file descriptors run out, and
//! the UDP peer table holds at most [`MAX_UDP_PEERS`] peers, forgetting those
//! silent for [`UDP_PEER_IDLE`].

use std::collections::{HashMap, HashSet};
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::Arc;
use std::time::{Duration, Instant};

use dccl::Codec;
use prost_reflect::ReflectMessage;
use tokio::io::{AsyncBufReadExt, AsyncRead, AsyncWriteExt, BufReader};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::{broadcast, mpsc, oneshot, watch};
use tokio::task::JoinSet;

pub mod lines;

#[cfg(test)]
mod golden;

use crate::event::UpdateSource;
use crate::event::{
    Control, CoreHandle, DaemonEvent, ForecastInput, LinkStatus, ModemEvent, Publish, SharedEvent,
};
use gobyd_protocol::{Reply, Topic};
use lines::{
    event_line, event_topic, lost, mac_cycle_reply, mac_switch_reply, network_reply, parse_request,
    publish_reply, ForecastRequest, Input,
};

pub use gobyd_protocol::MAX_LINE;

/// Capacity a connection's line buffer shrinks back to after a long line.
const KEPT_CAPACITY: usize = 64 * 1024;

/// Most UDP peers remembered (for their subscriptions and reply numbers);
/// a new peer beyond this replaces the one silent the longest.
pub const MAX_UDP_PEERS: usize = 256;

/// A UDP peer silent this long is forgotten.
pub const UDP_PEER_IDLE: Duration = Duration::from_secs(600);

/// Most UDP publishes waiting for their reply at once; beyond this a
/// publish is answered with an error (in its turn).
const MAX_UDP_WAITING: usize = 256;

/// Most UDP replies owed at once (publishes waiting for the core, and the
/// replies after them, which keep their peer's request order); while this
/// many are owed, datagrams wait in the socket's buffer.
const MAX_UDP_OWED: usize = 4096;

/// First and longest pause of the accept loop while descriptors run out.
const ACCEPT_BACKOFF: (Duration, Duration) = (Duration::from_millis(10), Duration::from_secs(1));

/// What a request line leads to.
enum Handled {
    /// The reply, at once.
    Reply(Reply),
    /// The reply at once, then event lines (the current state a
    /// subscription asked for).
    ReplyThen(Reply, Vec<String>),
    /// The reply line, once the core answers.
    Waiting(Answer),
}

/// A reply line still to come: the core's typed answer, rendered when it
/// arrives.
type Answer = Pin<Box<dyn Future<Output = Reply> + Send>>;

/// The line of the core's answer when it comes: `render` for an answer,
/// an error when the core stopped first.
fn answer<T: Send + 'static>(
    waiting: oneshot::Receiver<T>,
    render: impl FnOnce(T) -> Reply + Send + 'static,
) -> Answer {
    Box::pin(async move {
        match waiting.await {
            Ok(reply) => render(reply),
            Err(_) => shutting_down(),
        }
    })
}

/// The reply to a request the core can no longer take.
fn shutting_down() -> Reply {
    Reply::error("the daemon is shutting down")
}

/// What the next read of a [`LineReader`] found.
#[derive(Debug, PartialEq, Eq)]
pub enum LineRead {
    /// A complete line (trimmed).
    Line(String),
    /// A line passed the limit; what arrived of it was dropped and the rest
    /// up to its newline is skipped.
    TooLong,
    /// The peer closed the connection.
    End,
}

/// Splits a byte stream into lines of at most `max` bytes, never holding
/// more than `max` bytes of a line (plus one read buffer) however long it is.
/// [`next`](LineReader::next) is cancel-safe: its state lives in the reader.
#[derive(Debug)]
pub struct LineReader<R> {
    reader: BufReader<R>,
    line: Vec<u8>,
    max: usize,
    /// Skipping the rest of a line that was too long.
    skipping: bool,
}

impl<R: AsyncRead + Unpin> LineReader<R> {
    /// Reads lines of at most `max` bytes from `reader`.
    pub fn new(reader: R, max: usize) -> Self {
        Self {
            reader: BufReader::new(reader),
            line: Vec::new(),
            max,
            skipping: false,
        }
    }

    /// Bytes held for the line being read (its capacity).
    #[cfg(test)]
    pub fn held(&self) -> usize {
        self.line.capacity()
    }

    /// The next line, or [`LineRead::TooLong`] as soon as a line passes the
    /// limit.
    pub async fn next(&mut self) -> io::Result<LineRead> {
        loop {
            let available = self.reader.fill_buf().await?;
            if available.is_empty() {
                if !self.skipping && !self.line.is_empty() {
                    return Ok(LineRead::Line(self.take_line()));
                }
                return Ok(LineRead::End);
            }
            let (length, ends) = match available.iter().position(|&b| b == b'\n') {
                Some(i) => (i + 1, true),
                None => (available.len(), false),
            };
            if self.skipping {
                self.reader.consume(length);
                self.skipping = !ends;
                continue;
            }
            let content = length - usize::from(ends);
            if self.line.len() + content > self.max {
                self.reader.consume(length);
                self.line.clear();
                self.shrink();
                self.skipping = !ends;
                return Ok(LineRead::TooLong);
            }
            self.line.extend_from_slice(&available[..content]);
            self.reader.consume(length);
            if ends {
                return Ok(LineRead::Line(self.take_line()));
            }
        }
    }

    fn take_line(&mut self) -> String {
        let text = String::from_utf8_lossy(&self.line).trim().to_string();
        self.line.clear();
        self.shrink();
        text
    }

    fn shrink(&mut self) {
        if self.line.capacity() > KEPT_CAPACITY {
            self.line.shrink_to(KEPT_CAPACITY);
        }
    }
}

/// What the connections share.
#[derive(Debug, Clone)]
pub struct JsonInterface {
    /// The codec: clients may publish the types loaded in it.
    codec: Arc<Codec>,
    /// Where publish requests go.
    publish: mpsc::Sender<Publish>,
    /// Where driver-specific and file requests go.
    control: mpsc::Sender<Control>,
    /// Where the core's events come from.
    events: broadcast::Sender<SharedEvent>,
    /// Type names by DCCL id (for the queue size lines).
    names: Arc<HashMap<u32, String>>,
    /// The driver's last status (`None` before its first): sent once to a
    /// client as it subscribes to `modem`, so that it need not wait for the
    /// next change.
    driver_status: watch::Receiver<Option<modemdriver::DriverStatus>>,
    /// Every link's status as it stands: sent once to a client as it
    /// subscribes to `link`.
    link_status: watch::Receiver<Vec<LinkStatus>>,
    /// Where the link forecast's inputs go (`None`: none configured).
    forecast: Option<mpsc::Sender<ForecastInput>>,
}

impl JsonInterface {
    /// The interface to the core behind `core`.
    pub fn new(core: &CoreHandle) -> Self {
        JsonInterface {
            codec: core.codec.clone(),
            publish: core.publish.clone(),
            control: core.control.clone(),
            events: core.events.clone(),
            names: core.names.clone(),
            driver_status: core.driver_status.clone(),
            link_status: core.link_status.clone(),
            forecast: core.forecast.clone(),
        }
    }

    /// An event's line (`None`: clients do not see the event).
    fn line(&self, event: &DaemonEvent) -> Option<String> {
        event_line(event, |id| {
            self.names
                .get(&id)
                .cloned()
                .unwrap_or_else(|| format!("dccl id {id}"))
        })
    }

    /// Handles one request line: its reply now, or the channel it comes
    /// through.
    async fn handle_line(&self, line: &str, topics: &mut HashSet<Topic>) -> Handled {
        match parse_request(line, &self.codec) {
            Err(e) => Handled::Reply(Reply::error(e)),
            Ok(request) => self.handle_request(request, topics).await,
        }
    }

    /// Handles one request: its reply now, or the channel it comes through.
    async fn handle_request(&self, request: Input, topics: &mut HashSet<Topic>) -> Handled {
        match request {
            Input::Subscribe(t) => {
                let modem_now = !topics.contains(&Topic::Modem) && t.contains(&Topic::Modem);
                let link_now = !topics.contains(&Topic::Link) && t.contains(&Topic::Link);
                topics.extend(t);
                let mut all: Vec<Topic> = topics.iter().copied().collect();
                all.sort_by_key(|t| t.name());
                let reply = Reply::Subscribed { subscribed: all };
                // The driver's and the links' status as they stand, once:
                // later changes come as events.
                let mut now = Vec::new();
                let status = self.driver_status.borrow().clone();
                if let Some(status) = status.filter(|_| modem_now) {
                    now.push(DaemonEvent::modem(ModemEvent::Status(status)));
                }
                if link_now {
                    let links = self.link_status.borrow().clone();
                    now.extend(links.into_iter().map(DaemonEvent::Link));
                }
                let lines: Vec<String> = now
                    .iter()
                    .filter_map(|e| event_line(e, |id| format!("dccl id {id}")))
                    .collect();
                if lines.is_empty() {
                    Handled::Reply(reply)
                } else {
                    Handled::ReplyThen(reply, lines)
                }
            }
            Input::Publish(message) => {
                let (reply, waiting) = oneshot::channel();
                if self
                    .publish
                    .send(Publish::new(message, reply))
                    .await
                    .is_err()
                {
                    return Handled::Reply(shutting_down());
                }
                Handled::Waiting(answer(waiting, |reply| publish_reply(&reply)))
            }
            Input::Network(request) => {
                let (reply, outcome) = oneshot::channel();
                let control = Control::Network { request, reply };
                if self.control.send(control).await.is_err() {
                    return Handled::Reply(shutting_down());
                }
                Handled::Waiting(answer(outcome, |outcome| match outcome {
                    Ok(reply) => network_reply(&reply),
                    Err(e) => Reply::error(e),
                }))
            }
            Input::Forecast(request) => self.forecast_request(request).await,
            Input::MacUpdate(update) => {
                let (reply, outcome) = oneshot::channel();
                let control = Control::MacUpdate {
                    update,
                    from: UpdateSource::Json,
                    reply,
                };
                if self.control.send(control).await.is_err() {
                    return Handled::Reply(shutting_down());
                }
                Handled::Waiting(answer(outcome, mac_cycle_reply))
            }
            Input::MacSwitch(switch) => {
                let (reply, outcome) = oneshot::channel();
                let control = Control::MacSwitch {
                    mac: switch.mac,
                    keep_alive_seconds: switch.keep_alive_seconds,
                    from: UpdateSource::Json,
                    reply,
                };
                if self.control.send(control).await.is_err() {
                    return Handled::Reply(shutting_down());
                }
                Handled::Waiting(answer(outcome, mac_switch_reply))
            }
            Input::MacCycle => {
                let (reply, outcome) = oneshot::channel();
                if self
                    .control
                    .send(Control::MacCycle { reply })
                    .await
                    .is_err()
                {
                    return Handled::Reply(shutting_down());
                }
                Handled::Waiting(answer(outcome, |cycle| mac_cycle_reply(Ok(cycle))))
            }
            Input::DriverSpecific(message) => {
                let name = message.descriptor().full_name().to_string();
                let (reply, outcome) = oneshot::channel();
                let control = Control::DriverSpecific { message, reply };
                if self.control.send(control).await.is_err() {
                    return Handled::Reply(shutting_down());
                }
                Handled::Waiting(answer(outcome, move |outcome| match outcome {
                    Ok(()) => Reply::DriverSpecific {
                        driver_specific: name,
                    },
                    Err(e) => Reply::error(e),
                }))
            }
        }
    }

    /// Hands a request of the link forecast to it.
    async fn forecast_request(&self, request: ForecastRequest) -> Handled {
        let Some(forecast) = &self.forecast else {
            return Handled::Reply(Reply::error(
                "no link forecast: the configuration has no forecast section",
            ));
        };
        let (input, handled) = match request {
            ForecastRequest::Ctd(samples) => {
                let (reply, waiting) = oneshot::channel();
                let input = ForecastInput::Ctd {
                    samples,
                    reply: Some(reply),
                };
                let handled = Handled::Waiting(answer(waiting, |taken| match taken {
                    Ok(n) => Reply::Ctd { ctd: n },
                    Err(e) => Reply::error(e),
                }));
                (input, handled)
            }
            ForecastRequest::Nav(nav) => {
                let input = ForecastInput::Nav {
                    x: Some(nav.x),
                    y: Some(nav.y),
                    depth: Some(nav.depth),
                    lat: None,
                    lon: None,
                };
                (input, Handled::Reply(Reply::Nav { nav }))
            }
            ForecastRequest::Forecast => {
                let (reply, waiting) = oneshot::channel();
                let input = ForecastInput::Request { reply: Some(reply) };
                let handled =
                    Handled::Waiting(answer(waiting, |wait| Reply::Forecast { forecast: wait }));
                (input, handled)
            }
        };
        if forecast.send(input).await.is_err() {
            return Handled::Reply(shutting_down());
        }
        handled
    }

    /// Accepts TCP clients until the task is dropped. While file
    /// descriptors run out, it pauses between attempts (10 ms doubling up
    /// to 1 s) and logs once until a connection is accepted again.
    pub async fn serve_tcp(self, listener: TcpListener) {
        let mut connections = JoinSet::new();
        let mut backoff = ACCEPT_BACKOFF.0;
        let mut exhausted = false;
        loop {
            tokio::select! {
                accepted = listener.accept() => match accepted {
                    Ok((stream, peer)) => {
                        if exhausted {
                            tracing::info!("JSON interface: accepting connections again");
                            exhausted = false;
                            backoff = ACCEPT_BACKOFF.0;
                        }
                        tracing::info!(%peer, "JSON client connected");
                        connections.spawn(self.clone().serve_connection(stream, peer));
                    }
                    Err(e) if out_of_descriptors(&e) => {
                        if !exhausted {
                            tracing::warn!(
                                "JSON interface: cannot accept connections ({e}); pausing until descriptors are free"
                            );
                            exhausted = true;
                        }
                        tokio::time::sleep(backoff).await;
                        backoff = (backoff * 2).min(ACCEPT_BACKOFF.1);
                    }
                    Err(e) => tracing::warn!("JSON interface: accept failed: {e}"),
                },
                Some(_) = connections.join_next(), if !connections.is_empty() => {}
            }
        }
    }

    async fn serve_connection(self, stream: TcpStream, peer: SocketAddr) {
        let (read, mut write) = stream.into_split();
        let mut lines = LineReader::new(read, MAX_LINE);
        let mut events = self.events.subscribe();
        let mut topics = HashSet::new();
        // Number of the last request line.
        let mut number = 0u64;
        // The replies owed, in request order: publishes are pipelined.
        let mut owed = Pipeline::default();
        // A request other than a publish, read while replies were owed: it
        // is handled once they are sent (a subscription changes what this
        // connection sends only after the replies before it).
        let mut held: Option<(u64, Input)> = None;
        // What to write next (replies and event lines, each with its
        // newline), written in one go.
        let mut out = String::new();
        // The client closed its side: what it is owed is still sent.
        let mut ended = false;
        loop {
            owed.ready_lines(&mut out);
            if owed.is_empty() {
                if let Some((n, request)) = held.take() {
                    let handled = self.handle_request(request, &mut topics).await;
                    owed.push(n, handled);
                    owed.ready_lines(&mut out);
                }
            }
            if !out.is_empty() {
                if write.write_all(out.as_bytes()).await.is_err() {
                    break;
                }
                out.clear();
                if out.capacity() > KEPT_CAPACITY {
                    out.shrink_to(KEPT_CAPACITY);
                }
            }
            if ended && held.is_none() && owed.is_empty() {
                break;
            }
            let reading = !ended && held.is_none() && owed.len() < MAX_PIPELINED;
            tokio::select! {
                read = lines.next(), if reading => match read {
                    Ok(LineRead::End) => ended = true,
                    Ok(LineRead::TooLong) => {
                        number += 1;
                        owed.push(
                            number,
                            Handled::Reply(Reply::error(format!(
                                "line too long: the limit is {MAX_LINE} bytes; the rest of the line is skipped"
                            ))),
                        );
                    }
                    Ok(LineRead::Line(text)) if text.is_empty() => {}
                    Ok(LineRead::Line(text)) => {
                        number += 1;
                        match parse_request(&text, &self.codec) {
                            Err(e) => owed.push(number, Handled::Reply(Reply::error(e))),
                            Ok(request @ Input::Publish(_)) => {
                                let handled = self.handle_request(request, &mut topics).await;
                                owed.push(number, handled);
                            }
                            Ok(request) if owed.is_empty() => {
                                let handled = self.handle_request(request, &mut topics).await;
                                owed.push(number, handled);
                            }
                            Ok(request) => held = Some((number, request)),
                        }
                    }
                    Err(e) => {
                        tracing::info!(%peer, "JSON client read failed: {e}");
                        break;
                    }
                },
                () = owed.first_answered(), if owed.waits() => {}
                event = events.recv() => match event {
                    Ok(event) if wanted(&event, &topics) => {
                        if let Some(line) = self.line(&event) {
                            out.push_str(&line);
                            out.push('\n');
                        }
                    }
                    Ok(_) => {}
                    Err(broadcast::error::RecvError::Lagged(n)) if topics.is_empty() => {
                        tracing::info!(%peer, "JSON client read too slowly: {n} events not sent");
                    }
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        out.push_str(&lost(n).line());
                        out.push('\n');
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                },
            }
        }
        tracing::info!(%peer, "JSON client disconnected");
    }

    /// Serves UDP peers until the task is dropped. Every datagram gets a
    /// reply for each of its lines (an empty or unreadable datagram gets an
    /// error), one reply per datagram, sent in the order of the peer's
    /// requests: a reply waits for those before it. Replies to publishes
    /// are sent when the core answers, while other datagrams are read (and
    /// answered in their turn).
    pub async fn serve_udp(self, socket: UdpSocket) {
        let socket = Arc::new(socket);
        let mut events = self.events.subscribe();
        let mut peers = UdpPeers::default();
        // Replies owed: each sends once the reply before it (its peer's
        // tail) is sent and its own is ready.
        let mut waiting: JoinSet<()> = JoinSet::new();
        // Publishes among them still waiting for the core.
        let publishes = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let mut buf = vec![0u8; 65_536];
        loop {
            tokio::select! {
                got = socket.recv_from(&mut buf), if waiting.len() < MAX_UDP_OWED => {
                    let (n, from) = match got {
                        Ok(got) => got,
                        Err(e) => {
                            tracing::debug!("JSON UDP interface: receive failed: {e}");
                            continue;
                        }
                    };
                    let text = String::from_utf8_lossy(&buf[..n]).to_string();
                    let peer = peers.touch(from, Instant::now());
                    let mut lines: Vec<&str> =
                        text.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
                    if lines.is_empty() {
                        lines.push("");
                    }
                    for line in lines {
                        peer.replies += 1;
                        let number = peer.replies;
                        let busy = publishes.load(std::sync::atomic::Ordering::Relaxed)
                            >= MAX_UDP_WAITING;
                        let handled = if line.is_empty() {
                            Handled::Reply(Reply::error("empty datagram: expected a JSON request"))
                        } else if busy {
                            Handled::Reply(Reply::error("busy: too many publishes waiting; send again later"))
                        } else {
                            self.handle_line(line, &mut peer.topics).await
                        };
                        let ready = match handled {
                            Handled::Reply(reply) => Ok(vec![reply.numbered(number).line()]),
                            Handled::ReplyThen(reply, events) => {
                                let mut datagrams = vec![reply.numbered(number).line()];
                                datagrams.extend(events);
                                Ok(datagrams)
                            }
                            Handled::Waiting(reply) => Err(reply),
                        };
                        let tail = peer.tail.take().and_then(|mut tail| (!tail.is_sent()).then_some(tail));
                        match (ready, tail) {
                            // Nothing owed before it: sent now.
                            (Ok(datagrams), None) => {
                                for datagram in datagrams {
                                    let _ = socket.send_to(datagram.as_bytes(), from).await;
                                }
                            }
                            (ready, tail) => {
                                let (sent, next_tail) = ReplySent::new();
                                peer.tail = Some(next_tail);
                                let socket = socket.clone();
                                let reply = match ready {
                                    Ok(datagrams) => Ok(datagrams),
                                    Err(reply) => {
                                        publishes.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                                        let publishes = publishes.clone();
                                        Err(async move {
                                            let line = reply.await;
                                            publishes.fetch_sub(1, std::sync::atomic::Ordering::Relaxed);
                                            line.numbered(number).line()
                                        })
                                    }
                                };
                                waiting.spawn(async move {
                                    let datagrams = match reply {
                                        Ok(datagrams) => datagrams,
                                        Err(reply) => vec![reply.await],
                                    };
                                    if let Some(tail) = tail {
                                        tail.wait().await;
                                    }
                                    for datagram in datagrams {
                                        let _ = socket.send_to(datagram.as_bytes(), from).await;
                                    }
                                    drop(sent);
                                });
                            }
                        }
                    }
                }
                Some(_) = waiting.join_next(), if !waiting.is_empty() => {}
                event = events.recv() => match event {
                    Ok(event) => {
                        // Rendered once, for every peer that wants it.
                        let mut line = None;
                        for (addr, peer) in &peers.peers {
                            if !wanted(&event, &peer.topics) {
                                continue;
                            }
                            if let Some(line) = line.get_or_insert_with(|| self.line(&event)) {
                                let _ = socket.send_to(line.as_bytes(), addr).await;
                            }
                        }
                    }
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        tracing::warn!("JSON UDP interface lost {n} events");
                        let line = lost(n).line();
                        for (addr, peer) in &peers.peers {
                            if !peer.topics.is_empty() {
                                let _ = socket.send_to(line.as_bytes(), addr).await;
                            }
                        }
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                },
            }
        }
    }
}

/// Publishes a TCP connection reads ahead of their replies: up to this
/// many replies owed at once, then reading waits.
pub const MAX_PIPELINED: usize = 256;

/// A reply owed to a TCP client: ready, or the core's answer to come.
enum Owed {
    Ready(String),
    Waiting(Answer),
}

/// The replies a TCP connection owes, in request order, each with its
/// request's number: a reply is written once every reply before it is.
#[derive(Default)]
struct Pipeline {
    owed: std::collections::VecDeque<(u64, Owed)>,
}

impl Pipeline {
    /// The reply of request `number`.
    fn push(&mut self, number: u64, handled: Handled) {
        let owed = match handled {
            Handled::Reply(reply) => Owed::Ready(reply.numbered(number).line()),
            Handled::ReplyThen(reply, events) => {
                let mut text = reply.numbered(number).line();
                for event in events {
                    text.push('\n');
                    text.push_str(&event);
                }
                Owed::Ready(text)
            }
            Handled::Waiting(answer) => Owed::Waiting(answer),
        };
        self.owed.push_back((number, owed));
    }

    fn len(&self) -> usize {
        self.owed.len()
    }

    fn is_empty(&self) -> bool {
        self.owed.is_empty()
    }

    /// Whether the first reply owed is still to come from the core.
    fn waits(&self) -> bool {
        matches!(self.owed.front(), Some((_, Owed::Waiting(_))))
    }

    /// Waits for the core's answer to the first reply owed (cancel-safe:
    /// the answer is polled in place and kept once it came).
    async fn first_answered(&mut self) {
        let Some((number, owed)) = self.owed.front_mut() else {
            return std::future::pending().await;
        };
        let Owed::Waiting(answer) = owed else {
            return;
        };
        let reply = answer.await;
        *owed = Owed::Ready(reply.numbered(*number).line());
    }

    /// Appends the replies ready at the front, each with its newline, to
    /// `out`.
    fn ready_lines(&mut self, out: &mut String) {
        while let Some((_, Owed::Ready(_))) = self.owed.front() {
            let Some((_, Owed::Ready(line))) = self.owed.pop_front() else {
                unreachable!("checked");
            };
            out.push_str(&line);
            out.push('\n');
        }
    }
}

/// What the UDP interface remembers of a peer.
#[derive(Debug, Default)]
struct UdpPeer {
    topics: HashSet<Topic>,
    /// Number of the last request line.
    replies: u64,
    last_seen: Option<Instant>,
    /// The last reply owed to it, while it is not sent: the next reply
    /// waits for it.
    tail: Option<ReplySent>,
}

/// Tells when a UDP reply was sent (or given up): the holder of the
/// sending half drops it then.
#[derive(Debug)]
struct ReplySent(oneshot::Receiver<()>);

impl ReplySent {
    /// The sending half (drop it once the reply is sent) and its watch.
    fn new() -> (oneshot::Sender<()>, ReplySent) {
        let (tx, rx) = oneshot::channel();
        (tx, ReplySent(rx))
    }

    /// Whether the reply was sent already.
    fn is_sent(&mut self) -> bool {
        !matches!(self.0.try_recv(), Err(oneshot::error::TryRecvError::Empty))
    }

    /// Waits until the reply is sent.
    async fn wait(self) {
        let _ = self.0.await;
    }
}

/// The UDP peers heard from, at most [`MAX_UDP_PEERS`], none silent for
/// longer than [`UDP_PEER_IDLE`].
#[derive(Debug, Default)]
struct UdpPeers {
    peers: HashMap<SocketAddr, UdpPeer>,
}

impl UdpPeers {
    /// The peer at `addr`, heard from at `now` (remembered if new).
    fn touch(&mut self, addr: SocketAddr, now: Instant) -> &mut UdpPeer {
        if !self.peers.contains_key(&addr) {
            self.peers.retain(|_, p| {
                p.last_seen
                    .is_some_and(|t| now.duration_since(t) < UDP_PEER_IDLE)
            });
            if self.peers.len() >= MAX_UDP_PEERS {
                let oldest = self
                    .peers
                    .iter()
                    .min_by_key(|(_, p)| p.last_seen)
                    .map(|(a, _)| *a);
                if let Some(oldest) = oldest {
                    self.peers.remove(&oldest);
                }
            }
        }
        let peer = self.peers.entry(addr).or_default();
        peer.last_seen = Some(now);
        peer
    }
}

/// True for the errors of running out of file descriptors (EMFILE, ENFILE),
/// which last until some are closed.
fn out_of_descriptors(e: &io::Error) -> bool {
    const EMFILE: i32 = 24;
    const ENFILE: i32 = 23;
    matches!(e.raw_os_error(), Some(EMFILE | ENFILE))
}

fn wanted(event: &DaemonEvent, topics: &HashSet<Topic>) -> bool {
    match event_topic(event) {
        None => true,
        Some(topic) => topics.contains(&topic),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn lines_are_cut_off_at_their_limit_as_they_arrive() {
        let (mut client, server) = tokio::io::duplex(4096);
        let mut lines = LineReader::new(server, 1000);
        let writer = tokio::spawn(async move {
            client.write_all(b"short\n").await.unwrap();
            // 100 000 bytes, no newline yet.
            for _ in 0..100 {
                client.write_all(&[b'x'; 1000]).await.unwrap();
            }
            client.write_all(b"\nafter\n").await.unwrap();
        });
        assert_eq!(lines.next().await.unwrap(), LineRead::Line("short".into()));
        assert_eq!(lines.next().await.unwrap(), LineRead::TooLong);
        // Reported before the line ends, and nothing of it is held.
        assert!(lines.held() <= 1000, "{}", lines.held());
        assert_eq!(lines.next().await.unwrap(), LineRead::Line("after".into()));
        writer.await.unwrap();
        assert_eq!(lines.next().await.unwrap(), LineRead::End);
    }

    #[tokio::test]
    async fn the_buffer_shrinks_back_after_a_long_line() {
        let long = "y".repeat(500_000);
        let input = format!("{long}\nz\n");
        let mut lines = LineReader::new(input.as_bytes(), MAX_LINE);
        assert_eq!(lines.next().await.unwrap(), LineRead::Line(long));
        assert!(lines.held() <= KEPT_CAPACITY, "{}", lines.held());
        assert_eq!(lines.next().await.unwrap(), LineRead::Line("z".into()));
    }

    #[test]
    fn the_udp_peer_table_is_bounded_and_forgets_silent_peers() {
        let mut peers = UdpPeers::default();
        let start = Instant::now();
        let addr = |i: usize| SocketAddr::from(([127, 0, 0, 1], 10_000 + i as u16));
        for i in 0..MAX_UDP_PEERS + 10 {
            peers.touch(addr(i), start + Duration::from_millis(i as u64));
        }
        assert_eq!(peers.peers.len(), MAX_UDP_PEERS);
        assert!(!peers.peers.contains_key(&addr(0)));
        // Much later, a new peer: every silent one is forgotten.
        peers.touch(addr(9_000), start + UDP_PEER_IDLE * 2);
        assert_eq!(peers.peers.len(), 1);
    }
}
