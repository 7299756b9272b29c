//! The shared "water" of the simulator's nodes in one process.

use std::collections::HashMap;
use std::sync::{Arc, LazyLock, Mutex, Weak};
use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::observer::Observer;
use super::reception::Position;

/// A packet put on the water.
#[derive(Debug, Clone)]
pub struct Airborne {
    /// Modem id of the sender.
    pub src: i32,
    /// The sender's packet number (1, 2, ...).
    pub seq: u64,
    /// Where the sender is.
    pub position: Position,
    /// When the sender started sending.
    pub start: Instant,
    /// Time on the water.
    pub duration: Duration,
    /// What it carries.
    pub transmission: ModemTransmission,
}

/// The channel: every packet sent by one node is heard (subject to
/// propagation, loss and collisions) by every other node that has joined.
#[derive(Debug, Default)]
pub struct Medium {
    nodes: Mutex<Vec<(i32, mpsc::UnboundedSender<Arc<Airborne>>)>>,
    /// Told of every packet and its fate at each node, when set.
    observer: Option<Arc<dyn Observer>>,
}

static NAMED: LazyLock<Mutex<HashMap<String, Weak<Medium>>>> =
    LazyLock::new(|| Mutex::new(HashMap::new()));

impl Medium {
    /// A new channel of its own.
    pub fn new() -> Arc<Medium> {
        Arc::new(Medium::default())
    }

    /// A new channel of its own whose packets and their fates at each
    /// node are told to `observer` ([`super::observer`]).
    pub fn observed(observer: Arc<dyn Observer>) -> Arc<Medium> {
        Arc::new(Medium {
            nodes: Mutex::default(),
            observer: Some(observer),
        })
    }

    /// The observer, when the channel has one.
    pub fn observer(&self) -> Option<&dyn Observer> {
        self.observer.as_deref()
    }

    /// The in-process channel called `name`, created when no node uses it.
    pub fn named(name: &str) -> Arc<Medium> {
        let mut named = NAMED.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(medium) = named.get(name).and_then(Weak::upgrade) {
            return medium;
        }
        let medium = Medium::new();
        named.insert(name.to_string(), Arc::downgrade(&medium));
        medium
    }

    /// Joins as `modem_id`; packets of the other nodes arrive on the receiver.
    pub fn join(&self, modem_id: i32) -> mpsc::UnboundedReceiver<Arc<Airborne>> {
        let (tx, rx) = mpsc::unbounded_channel();
        self.lock().push((modem_id, tx));
        rx
    }

    /// Leaves the channel.
    pub fn leave(&self, modem_id: i32) {
        self.lock().retain(|(id, _)| *id != modem_id);
    }

    /// Puts a packet on the water for every other node.
    pub fn transmit(&self, packet: Arc<Airborne>) {
        let mut nodes = self.lock();
        nodes.retain(|(_, tx)| !tx.is_closed());
        for (id, tx) in nodes.iter() {
            if *id != packet.src {
                let _ = tx.send(packet.clone());
            }
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(i32, mpsc::UnboundedSender<Arc<Airborne>>)>> {
        self.nodes.lock().unwrap_or_else(|e| e.into_inner())
    }
}
