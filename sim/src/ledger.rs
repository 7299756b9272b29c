//! The ledger: every publication of a run and what became of it, from the
//! nodes' own events.
//!
//! A publication is entered when its stream makes it, then given its
//! journal id when its node accepts it. The node's queue events for that
//! id (sent, acknowledged, expired, dropped) are entered against it; a
//! reception at another node is matched to it by sender, type and the
//! DCCL bytes it was sent with (publications with the same content from
//! the same sender are matched in order of publication, so a repeat on
//! purpose counts as its own delivery and only copies beyond the number
//! published count as duplicates). At the end, each publication still in
//! its sender's journal is marked owed. The nodes' modem and medium
//! access events are counted as slot use ([`crate::slot_use`]).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;

use gobyd::event::{DaemonEvent, ModemEvent};
use modemdriver::TransmitOutcome;
use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use queue::QueueEvent;
use serde::Serialize;

use crate::carriage::Carriage;
use crate::discovery::{MacChange, MacRecord};
use crate::medium_log::MediumLog;
use crate::slot_use::{SlotTally, SlotUse};

/// Microseconds since the UNIX epoch (virtual time).
pub type Micros = i64;

/// One publication and its fate.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Publication {
    /// Index of the publishing node.
    pub src: usize,
    /// Index of its stream among the node's.
    pub stream: usize,
    /// Its number in its stream, from 0.
    pub seq: u64,
    /// Full name of its type.
    pub type_name: String,
    /// Index of the destination node (`None`: broadcast).
    pub dest: Option<usize>,
    /// When it was published.
    pub time: Micros,
    /// Its journal id at the sender, once accepted.
    pub entry: Option<u64>,
    /// Why the sender refused it, if it did.
    pub refused: Option<String>,
    /// How many times it was placed in a frame.
    pub sendings: u32,
    /// Each receiving node's receptions of it, in order.
    pub deliveries: BTreeMap<usize, Vec<Micros>>,
    /// When the sender heard its ack.
    pub acked: Option<Micros>,
    /// When it expired unsent or unacknowledged.
    pub expired: Option<Micros>,
    /// When its full queue dropped it.
    pub dropped: Option<Micros>,
    /// Still in the sender's journal at the end.
    pub owed: bool,
    /// The DCCL bytes it was first sent with.
    key: Option<Vec<u8>>,
}

/// A reception no publication accounts for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stray {
    /// The receiving node's index.
    pub receiver: usize,
    /// The source modem id it named.
    pub src: i32,
    /// Its type.
    pub type_name: String,
    /// When.
    pub time: Micros,
}

/// What a node said of one of its journal entries.
#[derive(Debug, Clone)]
enum EntryEvent {
    Sent(Vec<u8>),
    Acked,
    Expired,
    Dropped,
}

/// A node as the ledger knows it.
#[derive(Debug, Clone)]
pub struct LedgerNode {
    /// Its name.
    pub name: String,
    /// Its modem id.
    pub modem_id: i32,
    /// Its codec (to compare what was sent with what was received).
    pub codec: Arc<dccl::Codec>,
    /// Where each of its links goes, in order ([`crate::scenario::Node::links`]).
    pub links: Vec<crate::scenario::Medium>,
    /// The name of its link on the satellite, with `link` sections.
    pub satellite_link: Option<String>,
}

impl LedgerNode {
    /// Whether a modem event of this node's link `link` (its name; `None`
    /// for the one link of a top-level driver) happened on the satellite.
    pub fn on_satellite(&self, link: Option<&String>) -> bool {
        match link {
            Some(name) => self.satellite_link.as_ref() == Some(name),
            None => self.links == [crate::scenario::Medium::Satellite],
        }
    }
}

/// Every publication of a run; see the [module](self).
#[derive(Debug)]
pub struct Ledger {
    nodes: Vec<LedgerNode>,
    publications: Vec<Publication>,
    /// Publication by (node, journal id).
    entries: HashMap<(usize, u64), usize>,
    /// Events for a journal id not known yet (heard before the reply).
    pending: HashMap<(usize, u64), Vec<(Micros, EntryEvent)>>,
    /// Publications by (sender, type, bytes), in order of publication.
    by_content: HashMap<(usize, String, Vec<u8>), Vec<usize>>,
    stray: Vec<Stray>,
    /// Data packets sent, by (node, modem rate).
    packets: BTreeMap<(usize, i32), u64>,
    /// The nodes' slot use on the water.
    slots: SlotTally,
    /// The nodes' slot use on the satellite (`None`: no node has a link
    /// there).
    satellite: Option<SlotTally>,
    /// Auto-discovery's changes and the data packets, in time order.
    mac_log: Vec<MacRecord>,
    /// Which packets carried which journal entries.
    carriage: Carriage,
    /// What happened on the water.
    medium: MediumLog,
    /// When nodes were down (killed or their power cut, not started again
    /// yet): (node, from,
    /// until).
    down: Vec<(usize, Micros, Micros)>,
    /// What each power cut left of the nodes' logs, in time order.
    power_cuts: Vec<PowerCut>,
    /// What the console's replay of the run shows.
    replay: crate::replay::Kept,
    failure: Option<String>,
}

/// What one power cut did to a node's record logs ([`goby_store::power`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PowerCut {
    /// The node's name.
    pub node: String,
    /// When, seconds from the start of the run.
    pub at_s: f64,
    /// Each log of its data directory: what was written after its last
    /// sync and what of it the disk kept, in order of file name.
    pub files: Vec<CutLog>,
}

/// One record log at a power cut.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CutLog {
    /// The file, relative to the node's data directory.
    pub file: String,
    /// Bytes written since its last sync.
    pub unsynced_bytes: u64,
    /// Of those, the bytes the disk kept (a record torn when they end
    /// inside one; the daemon cuts it off as it starts).
    pub kept_bytes: u64,
}

impl Ledger {
    /// An empty ledger of `nodes` (in the scenario's order).
    pub fn new(nodes: Vec<LedgerNode>) -> Self {
        Ledger {
            slots: SlotTally::new(nodes.len()),
            satellite: nodes
                .iter()
                .any(|n| n.links.contains(&crate::scenario::Medium::Satellite))
                .then(|| SlotTally::new(nodes.len())),
            nodes,
            publications: Vec::new(),
            entries: HashMap::new(),
            pending: HashMap::new(),
            by_content: HashMap::new(),
            stray: Vec::new(),
            packets: BTreeMap::new(),
            mac_log: Vec::new(),
            carriage: Carriage::default(),
            medium: MediumLog::default(),
            down: Vec::new(),
            power_cuts: Vec::new(),
            replay: crate::replay::Kept::default(),
            failure: None,
        }
    }

    /// The nodes.
    pub fn nodes(&self) -> &[LedgerNode] {
        &self.nodes
    }

    /// Every publication, in order of publication.
    pub fn publications(&self) -> &[Publication] {
        &self.publications
    }

    /// Receptions no publication accounts for.
    pub fn stray(&self) -> &[Stray] {
        &self.stray
    }

    /// Data packets each node put on the water, by (node index, modem
    /// rate).
    pub fn packets(&self) -> &BTreeMap<(usize, i32), u64> {
        &self.packets
    }

    /// What the nodes did with the water.
    pub fn slot_use(&self) -> SlotUse {
        let names: Vec<&str> = self.nodes.iter().map(|n| n.name.as_str()).collect();
        self.slots.finish(&names)
    }

    /// What the nodes did with the satellite (`None`: no node has a link
    /// there).
    pub fn satellite_use(&self) -> Option<SlotUse> {
        let names: Vec<&str> = self.nodes.iter().map(|n| n.name.as_str()).collect();
        self.satellite.as_ref().map(|t| t.finish(&names))
    }

    /// Auto-discovery's changes of each node's cycle and every data packet
    /// sent or heard intact, in time order ([`crate::discovery`]).
    pub fn mac_log(&self) -> &[MacRecord] {
        &self.mac_log
    }

    /// Which data packets carried which journal entries.
    pub fn carriage(&self) -> &Carriage {
        &self.carriage
    }

    /// What happened on the water (empty until [`Ledger::set_medium`]).
    pub fn medium(&self) -> &MediumLog {
        &self.medium
    }

    /// Enters what happened on the water, at the end of the run.
    pub fn set_medium(&mut self, log: MediumLog) {
        self.medium = log;
    }

    /// Enters that node `node` was down (its gobyd killed, not started
    /// again yet) from `from` until `until`.
    pub fn down(&mut self, node: usize, from: Micros, until: Micros) {
        self.down.push((node, from, until));
    }

    /// When nodes were down (killed or their power cut, not started again
    /// yet): (node, from, until), in the order they came back.
    pub fn down_spans(&self) -> &[(usize, Micros, Micros)] {
        &self.down
    }

    /// What the run kept for its replay ([`crate::replay`]).
    pub fn kept(&self) -> &crate::replay::Kept {
        &self.replay
    }

    /// Keeps `event` of node `node` at `time` for the replay (if the
    /// console shows it); [`event`](Self::event) enters it in the ledger.
    pub fn keep(&mut self, node: usize, time: Micros, event: &gobyd::event::SharedEvent) {
        self.replay.event(node, time, event);
    }

    /// Keeps a publication of node `node` made at `time`, and its
    /// daemon's answer, for the replay.
    pub fn keep_published(
        &mut self,
        node: usize,
        time: Micros,
        message: &DynamicMessage,
        outcome: Result<Option<u64>, String>,
    ) {
        self.replay.published(node, time, message, outcome);
    }

    /// Enters what a power cut did.
    pub fn power_cut(&mut self, cut: PowerCut) {
        self.power_cuts.push(cut);
    }

    /// What the power cuts did, in time order.
    pub fn power_cuts(&self) -> &[PowerCut] {
        &self.power_cuts
    }

    /// Whether node `node` was down at some moment from `from` to `to`.
    pub fn was_down(&self, node: usize, from: Micros, to: Micros) -> bool {
        self.down
            .iter()
            .any(|&(n, down, up)| n == node && down <= to && from < up)
    }

    /// Why the run cannot be trusted (an event missed), if so.
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// Marks the run failed (the first reason is kept).
    pub fn fail(&mut self, reason: String) {
        self.failure.get_or_insert(reason);
    }

    /// Enters a publication made now; returns its index for
    /// [`accepted`](Self::accepted).
    pub fn publish(
        &mut self,
        src: usize,
        stream: usize,
        seq: u64,
        message: &DynamicMessage,
        dest: Option<usize>,
        time: Micros,
    ) -> usize {
        self.publications.push(Publication {
            src,
            stream,
            seq,
            type_name: message.descriptor().full_name().to_string(),
            dest,
            time,
            entry: None,
            refused: None,
            sendings: 0,
            deliveries: BTreeMap::new(),
            acked: None,
            expired: None,
            dropped: None,
            owed: false,
            key: None,
        });
        self.publications.len() - 1
    }

    /// The sender's answer to publication `index`: its journal id, or why
    /// it was refused.
    pub fn accepted(&mut self, index: usize, reply: Result<Option<u64>, String>) {
        let src = self.publications[index].src;
        match reply {
            Ok(Some(entry)) => {
                self.publications[index].entry = Some(entry);
                self.entries.insert((src, entry), index);
                for (time, event) in self.pending.remove(&(src, entry)).unwrap_or_default() {
                    self.apply(index, time, event);
                }
            }
            Ok(None) => {}
            Err(reason) => self.publications[index].refused = Some(reason),
        }
    }

    /// An event of node `node` at `time`.
    pub fn event(&mut self, node: usize, time: Micros, event: &DaemonEvent) {
        if let DaemonEvent::Modem { link, .. } = event {
            if self.nodes[node].on_satellite(link.as_ref()) {
                // The satellite's sessions: its own tally, not the water's
                // packets, cycles or losses.
                if let Some(tally) = &mut self.satellite {
                    tally.event(node, self.nodes[node].modem_id, event);
                }
                return;
            }
        }
        self.slots.event(node, self.nodes[node].modem_id, event);
        if let Some(what) = MacChange::of(event) {
            self.mac_log.push(MacRecord { node, time, what });
        }
        self.carriage.event(node, event);
        match event {
            DaemonEvent::Received { received, .. } => {
                let type_name = received.message.descriptor().full_name().to_string();
                let key = self.nodes[node].codec.encode(&received.message).ok();
                self.received(node, time, received.src, type_name, key);
            }
            DaemonEvent::Modem {
                event:
                    ModemEvent::Transmitted {
                        transmission,
                        outcome: TransmitOutcome::Sent,
                    },
                ..
            } if transmission.r#type() == TransmissionType::Data => {
                *self.packets.entry((node, transmission.rate())).or_default() += 1;
            }
            DaemonEvent::Queue {
                event,
                entry: Some(entry),
            } => {
                let event = match event {
                    QueueEvent::Sent { message, .. } => {
                        let key = self.nodes[node].codec.encode(message).unwrap_or_default();
                        EntryEvent::Sent(key)
                    }
                    QueueEvent::Acked { .. } => EntryEvent::Acked,
                    QueueEvent::Expired { .. } => EntryEvent::Expired,
                    QueueEvent::Dropped { .. } => EntryEvent::Dropped,
                    _ => return,
                };
                match self.entries.get(&(node, *entry)) {
                    Some(&index) => self.apply(index, time, event),
                    None => self
                        .pending
                        .entry((node, *entry))
                        .or_default()
                        .push((time, event)),
                }
            }
            _ => {}
        }
    }

    fn apply(&mut self, index: usize, time: Micros, event: EntryEvent) {
        let p = &mut self.publications[index];
        match event {
            EntryEvent::Sent(key) => {
                p.sendings += 1;
                if p.key.is_none() {
                    p.key = Some(key.clone());
                    self.by_content
                        .entry((p.src, p.type_name.clone(), key))
                        .or_default()
                        .push(index);
                }
            }
            EntryEvent::Acked => {
                p.acked.get_or_insert(time);
            }
            EntryEvent::Expired => {
                p.expired.get_or_insert(time);
            }
            EntryEvent::Dropped => {
                p.dropped.get_or_insert(time);
            }
        }
    }

    fn received(
        &mut self,
        receiver: usize,
        time: Micros,
        src: i32,
        type_name: String,
        key: Option<Vec<u8>>,
    ) {
        let stray = Stray {
            receiver,
            src,
            type_name: type_name.clone(),
            time,
        };
        let Some(sender) = self.nodes.iter().position(|n| n.modem_id == src) else {
            self.stray.push(stray);
            return;
        };
        let Some(key) = key else {
            self.stray.push(stray);
            return;
        };
        let candidates: Vec<usize> = self
            .by_content
            .get(&(sender, type_name, key))
            .into_iter()
            .flatten()
            .copied()
            .filter(|&i| self.publications[i].dest.is_none_or(|d| d == receiver))
            .collect();
        let first_new = candidates
            .iter()
            .copied()
            .find(|&i| !self.publications[i].deliveries.contains_key(&receiver));
        match first_new.or(candidates.first().copied()) {
            Some(i) => self.publications[i]
                .deliveries
                .entry(receiver)
                .or_default()
                .push(time),
            None => self.stray.push(stray),
        }
    }

    /// Marks owed each publication of `node` whose journal id is in `ids`
    /// (the entries left in its journal at the end).
    pub fn owed(&mut self, node: usize, ids: &BTreeSet<u64>) {
        for p in &mut self.publications {
            if p.src == node && p.entry.is_some_and(|e| ids.contains(&e)) {
                p.owed = true;
            }
        }
    }

    /// The nodes a publication is for: its destination, or every other
    /// node for a broadcast.
    pub fn receivers(&self, p: &Publication) -> Vec<usize> {
        match p.dest {
            Some(d) => vec![d],
            None => (0..self.nodes.len()).filter(|&n| n != p.src).collect(),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use gobyd::event::Reception;
    use queue::ReceivedMessage;

    fn command(note: &str) -> DynamicMessage {
        protos::goby::example::Command {
            destination: 2,
            action: 1,
            note: Some(note.into()),
            ..Default::default()
        }
        .transcode_to_dynamic()
    }

    /// Two nodes (modem ids 1 and 2) sharing a codec of the example types.
    pub(crate) fn ledger() -> Ledger {
        let mut codec = dccl::Codec::new();
        codec.load_type::<protos::goby::example::Command>().unwrap();
        let codec = Arc::new(codec);
        Ledger::new(
            [("a", 1), ("b", 2)]
                .map(|(name, modem_id)| LedgerNode {
                    name: name.into(),
                    modem_id,
                    codec: codec.clone(),
                    links: vec![crate::scenario::Medium::Water],
                    satellite_link: None,
                })
                .to_vec(),
        )
    }

    /// Publishes `message` at node 0 for node 1 as journal id `entry`, and
    /// tells the ledger it was sent.
    fn published(ledger: &mut Ledger, message: &DynamicMessage, entry: u64, time: Micros) -> usize {
        let index = ledger.publish(0, 0, entry, message, Some(1), time);
        ledger.accepted(index, Ok(Some(entry)));
        let sent = QueueEvent::Sent {
            message: message.clone(),
            id: entry,
            dccl_id: 125,
            frame: 0,
            awaiting_ack: true,
            link: 0,
        };
        ledger.event(
            0,
            time + 1,
            &DaemonEvent::Queue {
                event: sent,
                entry: Some(entry),
            },
        );
        index
    }

    /// Node 1 receives `message` from modem id `src` at `time`.
    pub(crate) fn receive(ledger: &mut Ledger, message: &DynamicMessage, src: i32, time: Micros) {
        let received = ReceivedMessage {
            message: message.clone(),
            dccl_id: 125,
            src,
            dest: 2,
            time: None,
            bytes: Vec::new(),
            identity: None,
        };
        let reception = Reception {
            link: None,
            recovered: false,
            route: None,
        };
        ledger.event(
            1,
            time,
            &DaemonEvent::Received {
                received,
                reception,
            },
        );
    }

    #[test]
    fn a_repeat_on_purpose_is_its_own_delivery_and_a_copy_beyond_is_a_duplicate() {
        let mut ledger = ledger();
        let same = command("same");
        let first = published(&mut ledger, &same, 10, 1_000);
        let second = published(&mut ledger, &same, 11, 2_000);
        receive(&mut ledger, &same, 1, 5_000);
        receive(&mut ledger, &same, 1, 6_000);
        receive(&mut ledger, &same, 1, 7_000);
        let p = ledger.publications();
        assert_eq!(p[first].deliveries[&1], [5_000, 7_000]);
        assert_eq!(p[second].deliveries[&1], [6_000]);
        // From a node of no publication of it, or of another content: stray.
        receive(&mut ledger, &same, 2, 8_000);
        receive(&mut ledger, &command("other"), 1, 8_000);
        assert_eq!(ledger.stray().len(), 2);
    }

    #[test]
    fn events_heard_before_the_journal_id_are_kept_for_it() {
        let mut ledger = ledger();
        let message = command("early");
        let index = ledger.publish(0, 0, 0, &message, Some(1), 1_000);
        let acked = QueueEvent::Acked {
            message: message.clone(),
            id: Some(7),
            dccl_id: 125,
            frame: 0,
            by: 2,
        };
        ledger.event(
            0,
            3_000,
            &DaemonEvent::Queue {
                event: acked,
                entry: Some(7),
            },
        );
        ledger.accepted(index, Ok(Some(7)));
        assert_eq!(ledger.publications()[index].acked, Some(3_000));
        ledger.owed(0, &BTreeSet::from([7]));
        assert!(ledger.publications()[index].owed);
    }
}
