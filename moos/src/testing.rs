//! A minimal MOOSDB for tests.
//!
//! [`MiniDb`] speaks the same wire protocol as a V10 MOOSDB and implements just enough
//! of it to test clients without a MOOS installation:
//!
//! - the handshake: protocol preamble check, unique client names (a second client of the
//!   same name gets a poison message), welcome with the community name and `asynchronous`;
//! - timing messages at the front of a packet are answered at once with the DB's time;
//! - registrations: a client gets every later write of the variable, and its current
//!   value at once if it has one; unregistrations;
//! - notifications: stored as the variable's value (a write of another data type is
//!   ignored, as MOOSDB does) and pushed to every subscribed client immediately.
//!
//! It does **not** implement registration intervals (every write is delivered),
//! wildcard registrations, server requests, the `DB_*` status variables, disconnecting
//! silent clients, or legacy synchronous clients. It is not a MOOSDB replacement.

use std::collections::{HashMap, HashSet};
use std::io;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::io::AsyncReadExt;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpListener, TcpStream, ToSocketAddrs};
use tokio::sync::{mpsc, watch};
use tokio::task::{JoinHandle, JoinSet};
use tokio::time::timeout;
use tracing::{debug, warn};

use crate::client::moos_time;
use crate::transport::{read_packet, write_messages};
use crate::wire::{
    check_preamble, decode_packet, DataType, Message, MessageKind, Value, PROTOCOL_PREAMBLE_LEN,
};

/// How long a new connection may take to send preamble and handshake.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// A minimal in-process MOOSDB for tests (see the module documentation for its limits).
pub struct MiniDb {
    addr: SocketAddr,
    db: Arc<Mutex<Db>>,
    shutdown: watch::Sender<bool>,
    task: JoinHandle<()>,
}

struct Db {
    community: String,
    values: HashMap<String, Message>,
    clients: HashMap<String, Peer>,
}

struct Peer {
    outbox: mpsc::UnboundedSender<Vec<Message>>,
    subscriptions: HashSet<String>,
}

impl MiniDb {
    /// Listens on `addr` (use `127.0.0.1:0` for a free port) for the community `community`.
    pub async fn start(addr: impl ToSocketAddrs, community: &str) -> io::Result<MiniDb> {
        let listener = TcpListener::bind(addr).await?;
        let addr = listener.local_addr()?;
        let db = Arc::new(Mutex::new(Db {
            community: community.to_string(),
            values: HashMap::new(),
            clients: HashMap::new(),
        }));
        let (shutdown, shutdown_rx) = watch::channel(false);
        let task = tokio::spawn(accept_loop(listener, db.clone(), shutdown_rx));
        Ok(MiniDb {
            addr,
            db,
            shutdown,
            task,
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.addr.port()
    }

    /// Current value of `var`, if any client has written it.
    pub fn value(&self, var: &str) -> Option<Value> {
        let db = lock(&self.db);
        db.values.get(var).and_then(|m| m.value().ok())
    }

    /// Names of the clients connected now, sorted.
    pub fn clients(&self) -> Vec<String> {
        let mut names: Vec<String> = lock(&self.db).clients.keys().cloned().collect();
        names.sort();
        names
    }

    /// Stops listening and closes every client connection; returns when all are closed.
    pub async fn stop(self) {
        let _ = self.shutdown.send(true);
        let _ = self.task.await;
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

async fn accept_loop(
    listener: TcpListener,
    db: Arc<Mutex<Db>>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut connections = JoinSet::new();
    loop {
        tokio::select! {
            _ = shutdown.changed() => break,
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    debug!(%peer, "MiniDb: new connection");
                    connections.spawn(serve(stream, db.clone()));
                }
                Err(e) => warn!("MiniDb: accept failed: {e}"),
            },
            // Reap finished connections so the set does not grow.
            Some(_) = connections.join_next(), if !connections.is_empty() => {}
        }
    }
    drop(listener);
    connections.shutdown().await;
    lock(&db).clients.clear();
}

/// Handshake, then serve one client until it disconnects.
async fn serve(stream: TcpStream, db: Arc<Mutex<Db>>) {
    let _ = stream.set_nodelay(true);
    let (mut rd, mut wr) = stream.into_split();
    let name = match timeout(HANDSHAKE_TIMEOUT, handshake(&mut rd, &mut wr, &db)).await {
        Ok(Ok(Some(name))) => name,
        Ok(Ok(None)) => return,
        Ok(Err(e)) => {
            debug!("MiniDb: handshake failed: {e}");
            return;
        }
        Err(_) => {
            debug!("MiniDb: handshake timed out");
            return;
        }
    };
    let (outbox_tx, mut outbox) = mpsc::unbounded_channel();
    lock(&db).clients.insert(
        name.clone(),
        Peer {
            outbox: outbox_tx,
            subscriptions: HashSet::new(),
        },
    );
    let writer = async {
        while let Some(messages) = outbox.recv().await {
            if write_messages(&mut wr, &messages).await.is_err() {
                break;
            }
        }
    };
    tokio::select! {
        _ = read_client(&mut rd, &name, &db) => {}
        _ = writer => {}
    }
    lock(&db).clients.remove(&name);
    debug!(client = %name, "MiniDb: client gone");
}

/// Returns the client's name, or `None` after refusing it.
async fn handshake(
    rd: &mut OwnedReadHalf,
    wr: &mut OwnedWriteHalf,
    db: &Mutex<Db>,
) -> Result<Option<String>, Box<dyn std::error::Error + Send + Sync>> {
    let mut preamble = [0u8; PROTOCOL_PREAMBLE_LEN];
    rd.read_exact(&mut preamble).await?;
    check_preamble(&preamble)?;
    let hello = decode_packet(&read_packet(rd).await?)?
        .into_iter()
        .next()
        .ok_or("empty handshake packet")?;
    if hello.kind != MessageKind::Data {
        return Err(format!("handshake message is {:?}, not Data", hello.kind).into());
    }
    let name = hello
        .string_text()
        .ok_or("client name is not UTF-8")?
        .to_string();
    let community = {
        let db = lock(db);
        if db.clients.contains_key(&name) {
            None
        } else {
            Some(db.community.clone())
        }
    };
    let Some(community) = community else {
        let mut poison = Message::new(MessageKind::Poison, "", moos_time());
        poison.data_type = DataType::String;
        poison.string = format!("A client of this name (\"{name}\") already exists").into_bytes();
        write_messages(wr, &[poison]).await?;
        return Ok(None);
    };
    let mut welcome = Message::new(MessageKind::Welcome, "", moos_time());
    welcome.double = 0.0;
    welcome.string = b"asynchronous".to_vec();
    welcome.community = community;
    write_messages(wr, &[welcome]).await?;
    Ok(Some(name))
}

/// Reads the client's packets and acts on them until the connection ends.
async fn read_client(rd: &mut OwnedReadHalf, name: &str, db: &Mutex<Db>) {
    loop {
        let messages = match read_packet(rd).await.map(|p| decode_packet(&p)) {
            Ok(Ok(m)) => m,
            Ok(Err(e)) => {
                warn!(client = %name, "MiniDb: bad packet, closing: {e}");
                return;
            }
            Err(e) => {
                debug!(client = %name, "MiniDb: connection ended: {e}");
                return;
            }
        };
        let mut db = lock(db);
        let mut reply = Vec::new();
        for (index, mut m) in messages.into_iter().enumerate() {
            match m.kind {
                MessageKind::Timing if index == 0 => {
                    m.double = moos_time();
                    m.double_aux = 0.0;
                    reply.push(m);
                }
                MessageKind::Register => {
                    if let Some(peer) = db.clients.get_mut(name) {
                        peer.subscriptions.insert(m.key.clone());
                    }
                    if let Some(current) = db.values.get(&m.key) {
                        reply.push(current.clone());
                    }
                }
                MessageKind::Unregister => {
                    if let Some(peer) = db.clients.get_mut(name) {
                        peer.subscriptions.remove(&m.key);
                    }
                }
                MessageKind::Notify => {
                    // Replies so far go out first, so the client's mail
                    // keeps the order of its messages.
                    if !reply.is_empty() {
                        if let Some(peer) = db.clients.get(name) {
                            let _ = peer.outbox.send(std::mem::take(&mut reply));
                        }
                    }
                    db.notify(m)
                }
                other => debug!(client = %name, kind = ?other, "MiniDb: ignoring message"),
            }
        }
        if !reply.is_empty() {
            if let Some(peer) = db.clients.get(name) {
                let _ = peer.outbox.send(reply);
            }
        }
    }
}

impl Db {
    fn notify(&mut self, mut m: Message) {
        if let Some(current) = self.values.get(&m.key) {
            if current.data_type != m.data_type {
                warn!(
                    var = %m.key,
                    source = %m.source,
                    "MiniDb: ignoring write of another data type"
                );
                return;
            }
        }
        if m.community.is_empty() {
            m.community = self.community.clone();
        }
        for peer in self.clients.values() {
            if peer.subscriptions.contains(&m.key) {
                let _ = peer.outbox.send(vec![m.clone()]);
            }
        }
        self.values.insert(m.key.clone(), m);
    }
}
