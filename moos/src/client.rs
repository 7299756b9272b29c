//! An asynchronous MOOS community client on tokio.
//!
//! [`MoosClient::connect`] opens a TCP connection to a MOOSDB, announces the V10
//! protocol, hands over the client name with the `asynchronous` handshake key (so the DB
//! pushes mail as it arrives) and waits for the DB's welcome. A background task then
//! owns the connection:
//!
//! - it sends a timing message every [`ClientConfig::heartbeat_period`], which keeps the
//!   DB from dropping the client as silent (MOOSDB's default client timeout is 5 s) and
//!   is answered by the DB, so the client notices a dead DB after
//!   [`ClientConfig::silence_timeout`] without a packet;
//! - it forwards registrations and notifications given to the [`MoosClient`] handle;
//! - it delivers every notification the DB pushes to the [`MailReceiver`];
//! - when the connection fails it reconnects after [`ClientConfig::reconnect_delay`]
//!   (doubling with each failed attempt up to 30 s while the MOOSDB is away) and
//!   registers again for every variable registered so far.
//!
//! Notifications made while disconnected are refused with [`ClientError::NotConnected`];
//! ones queued just before a connection drops are lost, as with the C++ MOOS clients.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use thiserror::Error;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};
use tokio::time::{sleep, sleep_until, timeout, Instant};
use tracing::{debug, info, warn};

use crate::transport::{read_packet, write_messages, TransportError};
use crate::wire::{
    decode_packet, protocol_preamble, Message, MessageKind, Value, WireError,
    HANDSHAKE_KEY_ASYNCHRONOUS,
};

/// Default MOOSDB host.
pub const DEFAULT_HOST: &str = "127.0.0.1";
/// Default MOOSDB port.
pub const DEFAULT_PORT: u16 = 9000;
/// Most messages the client puts in one outgoing packet.
const MAX_BATCH: usize = 256;
/// Longest outgoing delay the client accepts from the DB's timing replies.
const MAX_OUTGOING_DELAY: Duration = Duration::from_secs(1);

/// Seconds since the Unix epoch, the time base of MOOS time stamps.
pub fn moos_time() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0)
}

/// Where and how to connect.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientConfig {
    /// MOOSDB host name or address.
    pub host: String,
    /// MOOSDB port.
    pub port: u16,
    /// This client's name in the community; the DB refuses a second client of the same name.
    pub name: String,
    /// How often to send a timing message (heartbeat).
    pub heartbeat_period: Duration,
    /// Reconnect when the DB has sent nothing for this long.
    pub silence_timeout: Duration,
    /// Pause between connection attempts.
    pub reconnect_delay: Duration,
    /// Limit for TCP connect plus handshake.
    pub connect_timeout: Duration,
    /// Mail kept for the receiver before the client stops reading from the DB.
    pub mail_capacity: usize,
}

impl ClientConfig {
    /// Defaults for `name`: 127.0.0.1:9000, heartbeat 1 s, silence timeout 5 s,
    /// reconnect delay 1 s, connect timeout 5 s, room for 1024 mails.
    pub fn new(name: impl Into<String>) -> Self {
        ClientConfig {
            host: DEFAULT_HOST.to_string(),
            port: DEFAULT_PORT,
            name: name.into(),
            heartbeat_period: Duration::from_secs(1),
            silence_timeout: Duration::from_secs(5),
            reconnect_delay: Duration::from_secs(1),
            connect_timeout: Duration::from_secs(5),
            mail_capacity: 1024,
        }
    }

    /// The same configuration for another host and port.
    pub fn with_address(mut self, host: impl Into<String>, port: u16) -> Self {
        self.host = host.into();
        self.port = port;
        self
    }

    fn validate(&self) -> Result<(), ClientError> {
        let problem = if self.name.is_empty() {
            "client name is empty"
        } else if self.host.is_empty() {
            "host is empty"
        } else if self.heartbeat_period.is_zero() {
            "heartbeat_period is zero"
        } else if self.silence_timeout <= self.heartbeat_period {
            "silence_timeout must be longer than heartbeat_period"
        } else if self.connect_timeout.is_zero() {
            "connect_timeout is zero"
        } else if self.mail_capacity == 0 {
            "mail_capacity is zero"
        } else {
            return Ok(());
        };
        Err(ClientError::InvalidConfig(problem.to_string()))
    }

    fn address(&self) -> String {
        format!("{}:{}", self.host, self.port)
    }
}

/// A notification received from the DB.
#[derive(Debug, Clone, PartialEq)]
pub struct Mail {
    /// Variable name.
    pub key: String,
    /// The value written.
    pub value: Value,
    /// Client that wrote it.
    pub source: String,
    /// Extra source information.
    pub source_aux: String,
    /// Community it originated in.
    pub community: String,
    /// Writer's time stamp, seconds since the Unix epoch.
    pub time: f64,
}

impl Mail {
    /// The mail carried by a notify message; fails on text that is not UTF-8.
    pub fn from_message(message: Message) -> Result<Mail, WireError> {
        Ok(Mail {
            value: message.value()?,
            key: message.key,
            source: message.source,
            source_aux: message.source_aux,
            community: message.community,
            time: message.time,
        })
    }
}

/// Where the client's connection stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConnectionState {
    /// Trying to (re)connect.
    Connecting,
    /// Handshake done.
    Connected {
        /// Community the DB hosts.
        community: String,
        /// Counts successful handshakes: 1 for the first connection, 2 after one reconnect, ...
        session: u64,
    },
    /// The client was closed (or every handle dropped); it will not reconnect.
    Closed,
}

/// Receives the mail the DB pushes for registered variables.
pub type MailReceiver = mpsc::Receiver<Mail>;

/// Errors of the MOOS client.
#[derive(Debug, Error)]
pub enum ClientError {
    /// The configuration cannot work.
    #[error("invalid MOOS client configuration: {0}")]
    InvalidConfig(String),
    /// A variable name was empty.
    #[error("MOOS variable name is empty")]
    EmptyVariable,
    /// TCP connect failed.
    #[error("cannot connect to MOOSDB at {addr}: {source}")]
    Connect {
        /// host:port tried.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
    /// Connect plus handshake took too long.
    #[error("no welcome from MOOSDB at {addr} within {timeout:?}")]
    Timeout {
        /// host:port tried.
        addr: String,
        /// The limit.
        timeout: Duration,
    },
    /// The DB sent a poison message (for instance: the name is taken).
    #[error("MOOSDB at {addr} refused client {name:?}: {reason}")]
    Refused {
        /// host:port.
        addr: String,
        /// Our client name.
        name: String,
        /// The DB's reason.
        reason: String,
    },
    /// The handshake went wrong in another way.
    #[error("handshake with MOOSDB at {addr} failed: {detail}")]
    Handshake {
        /// host:port.
        addr: String,
        /// What happened.
        detail: String,
    },
    /// The connection failed.
    #[error("connection to MOOSDB at {addr} failed: {source}")]
    Transport {
        /// host:port.
        addr: String,
        /// Why.
        source: TransportError,
    },
    /// The DB sent nothing (not even timing replies) for too long.
    #[error("MOOSDB at {addr} sent nothing for {silence:?}")]
    Silent {
        /// host:port.
        addr: String,
        /// How long it was silent.
        silence: Duration,
    },
    /// A notification was refused because the client is not connected.
    #[error("not connected to MOOSDB; {var} not published")]
    NotConnected {
        /// Variable that was not published.
        var: String,
    },
    /// The client has been closed.
    #[error("MOOS client is closed")]
    Closed,
}

enum Command {
    Send(Message),
    Close,
}

struct Inner {
    name: String,
    commands: mpsc::UnboundedSender<Command>,
    registrations: Arc<Mutex<BTreeMap<String, f64>>>,
    state: watch::Receiver<ConnectionState>,
}

/// Handle to a running MOOS client; clones share the connection. The client stops when
/// [`MoosClient::close`] is called or the last handle is dropped.
#[derive(Clone)]
pub struct MoosClient {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for MoosClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MoosClient")
            .field("name", &self.inner.name)
            .field("state", &*self.inner.state.borrow())
            .finish()
    }
}

impl MoosClient {
    /// Connects and handshakes, then keeps the connection alive in a background task.
    /// Fails if the first connection cannot be made; later failures lead to reconnects.
    /// Must be called within a tokio runtime.
    pub async fn connect(config: ClientConfig) -> Result<(MoosClient, MailReceiver), ClientError> {
        config.validate()?;
        let (stream, welcome) = open(&config).await?;
        let (commands_tx, commands_rx) = mpsc::unbounded_channel();
        let (mail_tx, mail_rx) = mpsc::channel(config.mail_capacity);
        let (state_tx, state_rx) = watch::channel(ConnectionState::Connecting);
        let registrations = Arc::new(Mutex::new(BTreeMap::new()));
        let worker = Worker {
            addr: config.address(),
            config: config.clone(),
            commands: commands_rx,
            registrations: registrations.clone(),
            state: state_tx,
            mail: mail_tx,
            next_id: 0,
            session: 0,
            failures: 0,
        };
        // Publish "connected" before returning, so the handle can notify at once.
        let worker = worker.start_session(&welcome);
        tokio::spawn(worker.run(Some(stream)));
        let client = MoosClient {
            inner: Arc::new(Inner {
                name: config.name,
                commands: commands_tx,
                registrations,
                state: state_rx,
            }),
        };
        Ok((client, mail_rx))
    }

    /// This client's name.
    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// Subscribes to `var`, to be told at most once per `interval` (zero: every write).
    /// Remembered across reconnects; allowed while disconnected.
    pub fn register(&self, var: &str, interval: Duration) -> Result<(), ClientError> {
        check_var(var)?;
        let interval_s = interval.as_secs_f64();
        lock(&self.inner.registrations).insert(var.to_string(), interval_s);
        self.send(Message::register(var, interval_s, moos_time()))
    }

    /// Cancels a subscription to `var`.
    pub fn unregister(&self, var: &str) -> Result<(), ClientError> {
        check_var(var)?;
        lock(&self.inner.registrations).remove(var);
        self.send(Message::unregister(var, moos_time()))
    }

    /// Publishes the text `value` to `var`.
    pub fn notify_string(&self, var: &str, value: &str) -> Result<(), ClientError> {
        self.notify(Message::notify_string(var, value, moos_time()))
    }

    /// Publishes the double `value` to `var`.
    pub fn notify_double(&self, var: &str, value: f64) -> Result<(), ClientError> {
        self.notify(Message::notify_double(var, value, moos_time()))
    }

    /// Publishes the bytes `value` to `var` (MOOS binary string).
    pub fn notify_binary(&self, var: &str, value: &[u8]) -> Result<(), ClientError> {
        self.notify(Message::notify_binary(var, value, moos_time()))
    }

    /// A receiver of connection state changes.
    pub fn state(&self) -> watch::Receiver<ConnectionState> {
        self.inner.state.clone()
    }

    /// Whether the handshake with the DB is done and the connection is up.
    pub fn is_connected(&self) -> bool {
        matches!(
            *self.inner.state.borrow(),
            ConnectionState::Connected { .. }
        )
    }

    /// Sends what is queued, closes the connection and stops reconnecting; returns when done.
    pub async fn close(&self) {
        let _ = self.inner.commands.send(Command::Close);
        let mut state = self.state();
        let _ = state.wait_for(|s| *s == ConnectionState::Closed).await;
    }

    fn notify(&self, message: Message) -> Result<(), ClientError> {
        check_var(&message.key)?;
        match *self.inner.state.borrow() {
            ConnectionState::Connected { .. } => {}
            ConnectionState::Closed => return Err(ClientError::Closed),
            ConnectionState::Connecting => {
                return Err(ClientError::NotConnected {
                    var: message.key.clone(),
                })
            }
        }
        self.send(message)
    }

    fn send(&self, message: Message) -> Result<(), ClientError> {
        if *self.inner.state.borrow() == ConnectionState::Closed {
            return Err(ClientError::Closed);
        }
        self.inner
            .commands
            .send(Command::Send(message))
            .map_err(|_| ClientError::Closed)
    }
}

fn check_var(var: &str) -> Result<(), ClientError> {
    if var.is_empty() {
        Err(ClientError::EmptyVariable)
    } else {
        Ok(())
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// What the DB said in its welcome.
struct Welcome {
    community: String,
    asynchronous: bool,
}

/// TCP connect and handshake, within the connect timeout.
async fn open(config: &ClientConfig) -> Result<(TcpStream, Welcome), ClientError> {
    let addr = config.address();
    let attempt = async {
        let mut stream =
            TcpStream::connect(&addr)
                .await
                .map_err(|source| ClientError::Connect {
                    addr: addr.clone(),
                    source,
                })?;
        // MOOS disables Nagle by default; small messages should not wait.
        let _ = stream.set_nodelay(true);
        let welcome = handshake(&mut stream, &config.name, &addr).await?;
        Ok((stream, welcome))
    };
    timeout(config.connect_timeout, attempt)
        .await
        .map_err(|_| ClientError::Timeout {
            addr: addr.clone(),
            timeout: config.connect_timeout,
        })?
}

async fn handshake(stream: &mut TcpStream, name: &str, addr: &str) -> Result<Welcome, ClientError> {
    let transport = |source: TransportError| ClientError::Transport {
        addr: addr.to_string(),
        source,
    };
    stream
        .write_all(&protocol_preamble())
        .await
        .map_err(|e| transport(e.into()))?;
    write_messages(stream, &[Message::handshake(name, moos_time())])
        .await
        .map_err(transport)?;
    let packet = match read_packet(stream).await {
        Ok(p) => p,
        Err(TransportError::Closed) => {
            return Err(ClientError::Handshake {
                addr: addr.to_string(),
                detail: "the DB closed the connection without a welcome \
                         (does it speak MOOS V10?)"
                    .to_string(),
            })
        }
        Err(e) => return Err(transport(e)),
    };
    let reply = decode_packet(&packet)
        .map_err(|e| transport(e.into()))?
        .into_iter()
        .next()
        .ok_or_else(|| ClientError::Handshake {
            addr: addr.to_string(),
            detail: "the DB replied with an empty packet".to_string(),
        })?;
    match reply.kind {
        MessageKind::Welcome => Ok(Welcome {
            community: reply.community.clone(),
            asynchronous: reply
                .string_text()
                .is_some_and(|s| s.eq_ignore_ascii_case(HANDSHAKE_KEY_ASYNCHRONOUS)),
        }),
        MessageKind::Poison => Err(ClientError::Refused {
            addr: addr.to_string(),
            name: name.to_string(),
            reason: String::from_utf8_lossy(&reply.string).into_owned(),
        }),
        other => Err(ClientError::Handshake {
            addr: addr.to_string(),
            detail: format!("expected a welcome message, got {other:?}"),
        }),
    }
}

/// How a session ended.
enum SessionEnd {
    /// The user closed the client.
    Closed,
    /// The connection failed; reconnect.
    Failed(ClientError),
}

/// The background task owning the connection.
struct Worker {
    config: ClientConfig,
    addr: String,
    commands: mpsc::UnboundedReceiver<Command>,
    registrations: Arc<Mutex<BTreeMap<String, f64>>>,
    state: watch::Sender<ConnectionState>,
    mail: mpsc::Sender<Mail>,
    next_id: i32,
    session: u64,
    /// Reconnection attempts failed in a row (the pause doubles with each).
    failures: u32,
}

/// Longest pause between reconnection attempts while the MOOSDB is away.
const MAX_RECONNECT_PAUSE: Duration = Duration::from_secs(30);

/// The pause after `failures` failed attempts in a row: `base` doubled for
/// each, at most 30 s (or `base` if longer).
fn reconnect_pause(base: Duration, failures: u32) -> Duration {
    let grown = base.saturating_mul(1u32 << failures.min(16));
    grown.min(MAX_RECONNECT_PAUSE.max(base))
}

impl Worker {
    async fn run(mut self, mut first: Option<TcpStream>) {
        loop {
            if let Some(stream) = first.take() {
                match self.run_session(stream).await {
                    SessionEnd::Closed => break,
                    SessionEnd::Failed(e) => {
                        warn!(client = %self.config.name, "{e}; reconnecting");
                        self.state.send_replace(ConnectionState::Connecting);
                    }
                }
            }
            if self.pause_is_closed().await {
                break;
            }
            match open(&self.config).await {
                Ok((stream, welcome)) => {
                    if self.drop_stale_commands() {
                        break;
                    }
                    self.failures = 0;
                    self = self.start_session(&welcome);
                    first = Some(stream);
                }
                // The DB being down is expected while reconnecting; anything else is news.
                Err(e @ ClientError::Connect { .. }) => {
                    self.failures = self.failures.saturating_add(1);
                    debug!(client = %self.config.name, "reconnect failed: {e}")
                }
                Err(e) => {
                    self.failures = self.failures.saturating_add(1);
                    warn!(client = %self.config.name, "reconnect failed: {e}")
                }
            }
        }
        self.state.send_replace(ConnectionState::Closed);
        debug!(client = %self.config.name, "MOOS client closed");
    }

    /// Marks a new session as connected.
    fn start_session(mut self, welcome: &Welcome) -> Self {
        self.session += 1;
        if !welcome.asynchronous {
            warn!(
                addr = %self.addr,
                "MOOSDB does not announce asynchronous mail; mail arrives with heartbeat replies"
            );
        }
        info!(
            client = %self.config.name,
            addr = %self.addr,
            community = %welcome.community,
            session = self.session,
            "connected to MOOSDB"
        );
        self.state.send_replace(ConnectionState::Connected {
            community: welcome.community.clone(),
            session: self.session,
        });
        self
    }

    /// The pause before the next reconnection attempt: the reconnect delay,
    /// doubled for each attempt failed in a row, at most 30 s (or the
    /// reconnect delay if longer).
    fn reconnect_pause(&self) -> Duration {
        reconnect_pause(self.config.reconnect_delay, self.failures)
    }

    /// Waits the reconnect pause; true if the client was closed meanwhile.
    async fn pause_is_closed(&mut self) -> bool {
        let deadline = Instant::now() + self.reconnect_pause();
        loop {
            tokio::select! {
                _ = sleep_until(deadline) => return false,
                command = self.commands.recv() => match command {
                    None | Some(Command::Close) => return true,
                    Some(Command::Send(m)) => drop_while_disconnected(&m),
                },
            }
        }
    }

    /// Discards commands queued while disconnected (registrations are replayed from the
    /// registry instead); true if the client was closed.
    fn drop_stale_commands(&mut self) -> bool {
        loop {
            match self.commands.try_recv() {
                Ok(Command::Send(m)) => drop_while_disconnected(&m),
                Ok(Command::Close) => return true,
                Err(mpsc::error::TryRecvError::Empty) => return false,
                Err(mpsc::error::TryRecvError::Disconnected) => return true,
            }
        }
    }

    async fn run_session(&mut self, stream: TcpStream) -> SessionEnd {
        let (mut rd, mut wr) = stream.into_split();
        let delay = AtomicU64::new(0);
        let end = {
            let reader = read_loop(
                &mut rd,
                &self.mail,
                &delay,
                self.config.silence_timeout,
                &self.addr,
                &self.config.name,
            );
            // The first session has no registrations to replay: the registry
            // was empty at connect time, and every registration since is
            // queued as a command (a replay would register twice, and the DB
            // would send the current value twice).
            let replay = (self.session > 1).then_some(&*self.registrations);
            let writer = write_loop(
                &mut wr,
                &mut self.commands,
                &mut self.next_id,
                replay,
                &self.config,
                &self.addr,
                &delay,
            );
            tokio::select! {
                e = reader => SessionEnd::Failed(e),
                end = writer => end,
            }
        };
        if let SessionEnd::Closed = end {
            // Half-close and let the DB hang up, so nothing we sent is cut off.
            let _ = wr.shutdown().await;
            let mut sink = [0u8; 1024];
            let _ = timeout(Duration::from_secs(1), async {
                while let Ok(n) = rd.read(&mut sink).await {
                    if n == 0 {
                        break;
                    }
                }
            })
            .await;
        }
        end
    }
}

fn drop_while_disconnected(m: &Message) {
    if m.kind == MessageKind::Notify {
        warn!(var = %m.key, "MOOS connection lost before sending; notification dropped");
    }
}

/// Reads packets until the connection fails; delivers notifications as mail.
async fn read_loop(
    rd: &mut OwnedReadHalf,
    mail: &mpsc::Sender<Mail>,
    delay: &AtomicU64,
    silence: Duration,
    addr: &str,
    name: &str,
) -> ClientError {
    loop {
        let packet = match timeout(silence, read_packet(rd)).await {
            Err(_) => {
                return ClientError::Silent {
                    addr: addr.to_string(),
                    silence,
                }
            }
            Ok(Err(source)) => {
                return ClientError::Transport {
                    addr: addr.to_string(),
                    source,
                }
            }
            Ok(Ok(p)) => p,
        };
        let messages = match decode_packet(&packet) {
            Ok(m) => m,
            Err(e) => {
                // Framing is intact (the length was valid), so skip just this packet.
                warn!(addr, "dropping undecodable packet from MOOSDB: {e}");
                continue;
            }
        };
        for m in messages {
            match m.kind {
                MessageKind::Notify => {
                    let (key, source) = (m.key.clone(), m.source.clone());
                    match Mail::from_message(m) {
                        // A dropped receiver just means nobody reads mail.
                        Ok(letter) => {
                            let _ = mail.send(letter).await;
                        }
                        Err(e) => warn!(var = %key, source = %source, "dropping mail: {e}"),
                    }
                }
                MessageKind::Timing => {
                    let pause = outgoing_delay(m.double_aux).as_nanos() as u64;
                    delay.store(pause, Ordering::Relaxed);
                }
                MessageKind::Null | MessageKind::Welcome => {}
                MessageKind::Poison => {
                    return ClientError::Refused {
                        addr: addr.to_string(),
                        name: name.to_string(),
                        reason: String::from_utf8_lossy(&m.string).into_owned(),
                    }
                }
                other => debug!(kind = ?other, key = %m.key, "ignoring message from MOOSDB"),
            }
        }
    }
}

/// The pause between writes the DB asks for in its timing replies, capped.
fn outgoing_delay(seconds: f64) -> Duration {
    if seconds.is_finite() && seconds > 0.0 {
        Duration::from_secs_f64(seconds).min(MAX_OUTGOING_DELAY)
    } else {
        Duration::ZERO
    }
}

/// Sends the registrations to replay (after a reconnect), then heartbeats and
/// queued messages, until closed or failed.
async fn write_loop(
    wr: &mut OwnedWriteHalf,
    commands: &mut mpsc::UnboundedReceiver<Command>,
    next_id: &mut i32,
    replay: Option<&Mutex<BTreeMap<String, f64>>>,
    config: &ClientConfig,
    addr: &str,
    delay: &AtomicU64,
) -> SessionEnd {
    let now = moos_time();
    // The DB looks for a timing message at the front of a packet only.
    let mut batch = vec![Message::timing(now)];
    if let Some(registrations) = replay {
        batch.extend(
            lock(registrations)
                .iter()
                .map(|(var, interval)| Message::register(var.as_str(), *interval, now)),
        );
    }
    let period = config.heartbeat_period;
    let mut heartbeat = tokio::time::interval_at(Instant::now() + period, period);
    heartbeat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut closing = false;
    loop {
        if !batch.is_empty() {
            for m in &mut batch {
                m.source = config.name.clone();
                if m.kind != MessageKind::Timing {
                    m.id = *next_id;
                    *next_id = next_id.wrapping_add(1);
                }
            }
            if let Err(source) = write_messages(wr, &batch).await {
                return SessionEnd::Failed(ClientError::Transport {
                    addr: addr.to_string(),
                    source,
                });
            }
            batch.clear();
            let pause = Duration::from_nanos(delay.load(Ordering::Relaxed));
            if !pause.is_zero() {
                sleep(pause).await;
            }
        }
        if closing {
            return SessionEnd::Closed;
        }
        tokio::select! {
            _ = heartbeat.tick() => batch.push(Message::timing(moos_time())),
            command = commands.recv() => match command {
                None | Some(Command::Close) => closing = true,
                Some(Command::Send(m)) => {
                    batch.push(m);
                    while batch.len() < MAX_BATCH {
                        match commands.try_recv() {
                            Ok(Command::Send(m)) => batch.push(m),
                            Ok(Command::Close) | Err(mpsc::error::TryRecvError::Disconnected) => {
                                closing = true;
                                break;
                            }
                            Err(mpsc::error::TryRecvError::Empty) => break,
                        }
                    }
                }
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reconnection_pauses_grow_to_thirty_seconds_while_the_db_is_away() {
        let s = Duration::from_secs;
        let pauses: Vec<Duration> = (0..8).map(|n| reconnect_pause(s(1), n)).collect();
        assert_eq!(pauses, [s(1), s(2), s(4), s(8), s(16), s(30), s(30), s(30)]);
        assert_eq!(reconnect_pause(s(60), 3), s(60));
        assert_eq!(reconnect_pause(Duration::from_millis(100), 40), s(30));
    }

    #[test]
    fn config_is_checked() {
        let ok = ClientConfig::new("gobyd");
        assert_eq!(ok.address(), "127.0.0.1:9000");
        ok.validate().unwrap();
        for (mutate, needle) in [
            (
                Box::new(|c: &mut ClientConfig| c.name.clear()) as Box<dyn Fn(&mut ClientConfig)>,
                "name",
            ),
            (Box::new(|c| c.mail_capacity = 0), "mail_capacity"),
            (
                Box::new(|c| c.silence_timeout = c.heartbeat_period),
                "silence_timeout",
            ),
            (
                Box::new(|c| c.heartbeat_period = Duration::ZERO),
                "heartbeat",
            ),
        ] {
            let mut c = ClientConfig::new("gobyd");
            mutate(&mut c);
            let err = c.validate().unwrap_err().to_string();
            assert!(err.contains(needle), "{err}");
        }
    }

    #[test]
    fn outgoing_delay_is_sane() {
        assert_eq!(outgoing_delay(-1.0), Duration::ZERO);
        assert_eq!(outgoing_delay(f64::NAN), Duration::ZERO);
        assert_eq!(outgoing_delay(0.02), Duration::from_millis(20));
        assert_eq!(outgoing_delay(1e9), MAX_OUTGOING_DELAY);
    }
}
