//! The shared "water" of the simulator's nodes in one process.

use std::collections::{BTreeSet, HashMap, VecDeque};
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
    /// A fault of the simulation keeps it from the node it is handed to
    /// ([`Filter`]): that node does not hear it, and tells its observer so.
    pub kept: bool,
    /// A fault of the simulation garbled its frames on the way to the node
    /// it is handed to (its fate there is told as garbled, not heard).
    pub garbled: bool,
}

/// What becomes of a packet on its way to one receiver (its modem id):
/// the packet as that receiver hears it (the same, or changed), or `None`
/// when it does not reach it (the receiver is handed it marked
/// [`Airborne::kept`], so that its fate there is told). A simulation's faults (a link down, a modem
/// unplugged, garbled frames) are filters.
pub type Filter = Arc<dyn Fn(&Arc<Airborne>, i32) -> Option<Arc<Airborne>> + Send + Sync>;

/// The channel: every packet sent by one node is heard (subject to
/// propagation, loss and collisions) by every other node that has joined.
#[derive(Default)]
pub struct Medium {
    nodes: Mutex<Vec<(i32, mpsc::UnboundedSender<Arc<Airborne>>)>>,
    /// Told of every packet and its fate at each node, when set.
    observer: Option<Arc<dyn Observer>>,
    filter: Mutex<Option<Filter>>,
    /// On a satellite channel, the messages for each node at the gateway
    /// (its MT queue, or a shore station's MO), first in, first out, each
    /// from when it is there: they outlive the node's driver, as a
    /// gateway's queue outlives a vehicle's reboot or a shore's restart.
    mailboxes: Mutex<HashMap<i32, VecDeque<(Instant, ModemTransmission)>>>,
    /// Every node that ever joined (the nodes a broadcast is for, up or
    /// down).
    members: Mutex<BTreeSet<i32>>,
    /// Every node the gateway knows, when told beforehand ([`Medium::enrol`]):
    /// a message for another is refused.
    roster: Mutex<Option<BTreeSet<i32>>>,
}

/// Why the gateway refused a message ([`Medium::post`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refused {
    /// No node of that modem id is on the satellite.
    Unknown,
    /// The node's queue at the gateway holds this many already.
    Full(usize),
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refused::Unknown => write!(f, "no node of that modem id has an Iridium link"),
            Refused::Full(n) => write!(
                f,
                "its queue at the gateway is full ({n} messages, the satellite's queue_limit)"
            ),
        }
    }
}

impl std::fmt::Debug for Medium {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Medium")
            .field("nodes", &self.nodes)
            .field("observer", &self.observer)
            .field(
                "filtered",
                &self.filter.lock().map(|f| f.is_some()).unwrap_or(false),
            )
            .finish()
    }
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
            observer: Some(observer),
            ..Medium::default()
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
        self.members
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(modem_id);
        rx
    }

    /// Leaves the channel.
    pub fn leave(&self, modem_id: i32) {
        self.lock().retain(|(id, _)| *id != modem_id);
    }

    /// Passes every packet through `filter` on its way to each receiver
    /// from now on (in place of any filter before).
    pub fn set_filter(&self, filter: Filter) {
        *self.filter.lock().unwrap_or_else(|e| e.into_inner()) = Some(filter);
    }

    /// Puts a packet on the water for every other node (as the filter, if
    /// any, lets it reach each).
    pub fn transmit(&self, packet: Arc<Airborne>) {
        let filter = self
            .filter
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        let mut nodes = self.lock();
        nodes.retain(|(_, tx)| !tx.is_closed());
        for (id, tx) in nodes.iter() {
            if *id == packet.src {
                continue;
            }
            let heard = match &filter {
                None => packet.clone(),
                Some(filter) => filter(&packet, *id).unwrap_or_else(|| {
                    Arc::new(Airborne {
                        kept: true,
                        garbled: false,
                        ..(*packet).clone()
                    })
                }),
            };
            let _ = tx.send(heard);
        }
    }

    /// Tells the gateway beforehand which nodes are on the satellite (as a
    /// run that starts them all knows): a broadcast is for them, and a
    /// message for any other node is refused.
    pub fn enrol(&self, modem_ids: impl IntoIterator<Item = i32>) {
        *self.roster.lock().unwrap_or_else(|e| e.into_inner()) =
            Some(modem_ids.into_iter().collect());
    }

    /// The nodes a broadcast is for: those enrolled, else every node that
    /// ever joined the channel.
    pub fn members(&self) -> Vec<i32> {
        if let Some(roster) = &*self.roster.lock().unwrap_or_else(|e| e.into_inner()) {
            return roster.iter().copied().collect();
        }
        let members = self.members.lock().unwrap_or_else(|e| e.into_inner());
        members.iter().copied().collect()
    }

    /// Leaves `mt` at the gateway for node `modem_id` from `at`, behind
    /// what is there already (on its way or waiting), unless the node is
    /// not enrolled or `limit` messages are there for it.
    pub fn post(
        &self,
        modem_id: i32,
        at: Instant,
        mt: ModemTransmission,
        limit: usize,
    ) -> Result<(), Refused> {
        let roster = self.roster.lock().unwrap_or_else(|e| e.into_inner());
        if roster.as_ref().is_some_and(|r| !r.contains(&modem_id)) {
            return Err(Refused::Unknown);
        }
        drop(roster);
        let mut mailboxes = self.mailboxes.lock().unwrap_or_else(|e| e.into_inner());
        let queue = mailboxes.entry(modem_id).or_default();
        if queue.len() >= limit {
            return Err(Refused::Full(queue.len()));
        }
        queue.push_back((at, mt));
        Ok(())
    }

    /// The oldest message at the gateway for node `modem_id` by `now`,
    /// taken from there (`None`: none is there yet).
    pub fn collect(&self, modem_id: i32, now: Instant) -> Option<ModemTransmission> {
        let mut mailboxes = self.mailboxes.lock().unwrap_or_else(|e| e.into_inner());
        let queue = mailboxes.get_mut(&modem_id)?;
        match queue.front() {
            Some((at, _)) if *at <= now => queue.pop_front().map(|(_, mt)| mt),
            _ => None,
        }
    }

    /// How many messages are at the gateway for node `modem_id` by `now`.
    pub fn waiting(&self, modem_id: i32, now: Instant) -> usize {
        self.mailboxes
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&modem_id)
            .map_or(0, |q| q.iter().take_while(|(at, _)| *at <= now).count())
    }

    /// When the next message on its way to the gateway for node
    /// `modem_id` is there (`None`: none is on its way).
    pub fn next_arrival(&self, modem_id: i32, now: Instant) -> Option<Instant> {
        self.mailboxes
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&modem_id)?
            .iter()
            .map(|(at, _)| *at)
            .find(|at| *at > now)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(i32, mpsc::UnboundedSender<Arc<Airborne>>)>> {
        self.nodes.lock().unwrap_or_else(|e| e.into_inner())
    }
}
