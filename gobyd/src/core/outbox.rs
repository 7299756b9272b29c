//! The daemon's outbox: the queue manager with every accepted message in a
//! journal on disk until it is acknowledged, expires or is dropped, so that
//! a crash or restart of `gobyd` loses nothing. A message is encoded once:
//! the journal keeps its DCCL encoding and the queue sends those bytes.

use std::collections::HashMap;
use std::path::Path;
use std::sync::mpsc::Receiver;

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::ModemTransmission;
use queue::{
    Encoding, EntryId, Journal, JournalEntry, JournalError, MessageId, PushOptions, QueueError,
    QueueEvent, QueueManager,
};

/// Why a message was not accepted.
#[derive(Debug, thiserror::Error)]
pub enum OutboxError {
    /// The queue refused it (unconfigured type, value out of range in strict
    /// mode, too large, ...).
    #[error(transparent)]
    Queue(#[from] QueueError),
    /// It could not be written to the journal: it was not accepted.
    #[error(transparent)]
    Journal(#[from] JournalError),
}

/// What became of an accepted message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Accepted {
    /// Journaled and queued for sending.
    Queued(EntryId),
    /// Delivered at once without sending (addressed to this node, or a
    /// type that is never queued); not kept.
    Delivered,
}

/// A message found in the journal that could not be queued again.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReplayFailure {
    /// Type named by the journal record.
    pub message_name: String,
    /// Why it could not be queued.
    pub reason: String,
}

/// What opening the outbox found in the journal.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct OutboxReplay {
    /// Messages queued again.
    pub requeued: usize,
    /// Messages that could not be (their type is gone from the
    /// configuration, or they no longer encode); removed from the journal.
    pub failed: Vec<ReplayFailure>,
    /// Bytes of a torn or damaged journal tail that were dropped.
    pub discarded_bytes: u64,
}

/// The queue manager and its journal.
pub struct Outbox {
    queue: QueueManager,
    journal: Journal,
    events: Receiver<QueueEvent>,
    /// Journal entry of each queued message.
    entries: HashMap<MessageId, EntryId>,
    /// Messages without ack placed in frames of the transmission under way
    /// (of each link): they leave the journal once it went out, and are
    /// queued again if it failed.
    in_flight: Vec<(queue::LinkIndex, EntryId, DynamicMessage)>,
    /// Journal entries that left their queue for good but whose removal
    /// could not be written (a full disk): written again before each
    /// acceptance and each batch of events ([`Outbox::remove`]).
    unremoved: Vec<EntryId>,
    /// Removals written since the journal's last sync: synced before the
    /// events they go with are told ([`Outbox::sync_removals`]).
    removed_unsynced: bool,
}

impl std::fmt::Debug for Outbox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Outbox")
            .field("queue", &self.queue)
            .field("journal", &self.journal.path())
            .field("owed", &self.journal.len())
            .finish()
    }
}

impl Outbox {
    /// Opens the journal at `journal_path` and queues again every message it
    /// still owes.
    pub fn open(
        mut queue: QueueManager,
        journal_path: &Path,
    ) -> Result<(Self, OutboxReplay), OutboxError> {
        let events = queue.subscribe();
        let (mut journal, replay) = Journal::open(journal_path)?;
        // A message's journal id is its publication number on the wire.
        journal.skip_ids_to(queue::identity::start_number(
            &queue.entropy(),
            queue::identity::PUBLICATIONS,
        ));
        let mut outbox = Self {
            queue,
            journal,
            events,
            entries: HashMap::new(),
            in_flight: Vec::new(),
            unremoved: Vec::new(),
            removed_unsynced: false,
        };
        let mut report = OutboxReplay {
            discarded_bytes: replay.discarded_bytes,
            ..Default::default()
        };
        for entry in replay.entries {
            // It may have gone out before the restart.
            let options = PushOptions {
                created: Some(entry.time),
                number: Some(entry.id),
                resent: true,
                encoded: (entry.encoding == Encoding::Dccl).then(|| entry.message.clone()),
            };
            let queued = journaled_message(outbox.queue.codec(), &entry).and_then(|message| {
                outbox
                    .queue
                    .push(message, options)
                    .map_err(|e| e.to_string())
            });
            match queued {
                Ok(Some(id)) => {
                    outbox.entries.insert(id, entry.id);
                    report.requeued += 1;
                }
                Ok(None) => outbox.remove(entry.id),
                Err(reason) => {
                    outbox.remove(entry.id);
                    report.failed.push(ReplayFailure {
                        message_name: entry.message_name,
                        reason,
                    });
                }
            }
        }
        Ok((outbox, report))
    }

    /// The queue manager (sizes, codec, configuration).
    pub fn queue(&self) -> &QueueManager {
        &self.queue
    }

    /// Messages journaled and not yet acknowledged, expired or dropped.
    pub fn owed(&self) -> usize {
        self.journal.len()
    }

    /// Accepts a message for sending: appended to the journal, then queued
    /// (it may go out at once). `encoded`: its DCCL encoding with the
    /// queue's codec, when the caller made it already (it is made here
    /// otherwise); the journal keeps those bytes and the queue sends them.
    /// `created`: when its age (for its type's `ttl`) counts from
    /// (microseconds since the epoch; may be in the future, for a message
    /// meant to live longer than its type's `ttl`, as the network layer's
    /// carry their own lifetime), also after a restart; now when `None`.
    ///
    /// It survives a crash once the journal is synced: tell the client
    /// "accepted" only after a sync of [`sync_handle`](Self::sync_handle)
    /// (or [`sync`](Self::sync)).
    pub fn accept(
        &mut self,
        message: DynamicMessage,
        encoded: Option<Vec<u8>>,
        created: Option<queue::Micros>,
    ) -> Result<Accepted, OutboxError> {
        let encoded = match encoded {
            Some(encoded) => encoded,
            None => self
                .queue
                .codec()
                .encode(&message)
                .map_err(QueueError::from)?,
        };
        self.remove_again();
        let entry = self.journal.accept_unsynced(
            message.descriptor().full_name(),
            encoded.as_slice(),
            created.unwrap_or_else(|| self.queue.now()),
        )?;
        let options = PushOptions {
            created,
            number: Some(entry),
            resent: false,
            encoded: Some(encoded),
        };
        match self.queue.push(message, options) {
            Ok(Some(id)) => {
                self.entries.insert(id, entry);
                Ok(Accepted::Queued(entry))
            }
            Ok(None) => {
                self.remove(entry);
                Ok(Accepted::Delivered)
            }
            Err(e) => {
                self.remove(entry);
                Err(e.into())
            }
        }
    }

    /// The journal id the next accepted message will get.
    pub fn next_entry(&self) -> Option<EntryId> {
        self.journal.next_id()
    }

    /// The messages journaled and still owed, oldest first.
    pub fn journaled(&self) -> impl Iterator<Item = &queue::JournalEntry> {
        self.journal.entries()
    }

    /// Queues a message without journaling it (its owner keeps it on disk
    /// in its own way, as the network layer keeps its transfers): its
    /// events carry no journal entry. Returns its id in the queue.
    pub fn push_unjournaled(
        &mut self,
        message: DynamicMessage,
        options: PushOptions,
    ) -> Result<Option<queue::MessageId>, QueueError> {
        self.queue.push(message, options)
    }

    /// Waits until every accepted message is on disk.
    pub fn sync(&mut self) -> Result<(), JournalError> {
        self.journal.sync()
    }

    /// A handle whose `sync_data` makes every message accepted so far
    /// durable, for syncing off the caller's thread.
    pub fn sync_handle(&self) -> Result<goby_store::record_log::SyncHandle, JournalError> {
        self.journal.sync_handle()
    }

    /// Fills the frames of a data request of link `link` from the queues
    /// (0, the only one, when the configuration has no `link` sections;
    /// otherwise with the messages [`queue::links`]' rules let it carry),
    /// with messages of the types of DCCL ids `only` alone (empty: every
    /// type; a scripted TDMA slot's packet types).
    pub fn data_request(
        &mut self,
        request: &mut ModemTransmission,
        link: queue::LinkIndex,
        only: &[u32],
    ) -> Result<(), QueueError> {
        self.queue.handle_modem_data_request_of(request, link, only)
    }

    /// Hands a transmission (data or ack) received on link `link` to the
    /// queues; returns the frames that did not decode (the others are still
    /// delivered).
    pub fn receive(
        &mut self,
        transmission: &ModemTransmission,
        link: queue::LinkIndex,
    ) -> Vec<QueueError> {
        self.queue.handle_modem_receive(transmission, link)
    }

    /// The queue's links, to tell their states (`None`: one link).
    pub fn links_mut(&mut self) -> Option<&mut queue::Links> {
        self.queue.links_mut()
    }

    /// Empties the queue of a type and removes its messages from the
    /// journal (as expiry does); returns how many were flushed.
    pub fn flush(&mut self, name: &str) -> Result<usize, OutboxError> {
        let ids = self.queue.flush_ids(name)?;
        for id in &ids {
            if let Some(entry) = self.entries.remove(id) {
                self.remove(entry);
            }
        }
        Ok(ids.len())
    }

    /// Takes the messages of type `name` that `pick` chooses (given each
    /// one's queue id and message) as acknowledged by node `by`, though no
    /// ack of the link came ([`QueueManager::acknowledge_where`]): their
    /// [`QueueEvent::Acked`] events come with the next
    /// [`events`](Self::events), which removes them from the journal.
    /// Returns how many left.
    pub fn acknowledge_where(
        &mut self,
        name: &str,
        by: i32,
        pick: impl FnMut(queue::MessageId, &DynamicMessage) -> bool,
    ) -> Result<usize, OutboxError> {
        Ok(self.queue.acknowledge_where(name, by, pick)?)
    }

    /// Takes the unjournaled messages of type `name` that `pick` chooses
    /// out of the queue without an ack or an expiry
    /// ([`QueueManager::withdraw_where`]): the network layer takes back
    /// what it pushed with [`push_unjournaled`](Self::push_unjournaled).
    /// Returns their ids.
    pub fn withdraw_unjournaled(
        &mut self,
        name: &str,
        pick: impl FnMut(queue::MessageId, &DynamicMessage) -> bool,
    ) -> Result<Vec<queue::MessageId>, OutboxError> {
        Ok(self.queue.withdraw_where(name, pick)?)
    }

    /// Expires the messages older than their ttl.
    pub fn expire(&mut self) {
        self.queue.expire();
    }

    /// The queue events since the last call, each with the journal entry
    /// id (the id clients were given) of the message it is about: for
    /// sendings, acks, expiries and drops. Messages that left their queue
    /// for good are removed from the journal first, and the removals
    /// synced, so that a client told of an ack or an expiry is never told
    /// of it again after a power cut; messages sent without ack wait for
    /// [`transmitted`](Self::transmitted).
    pub fn events(&mut self) -> Vec<(QueueEvent, Option<EntryId>)> {
        self.remove_again();
        let events: Vec<QueueEvent> = self.events.try_iter().collect();
        let mut out = Vec::with_capacity(events.len());
        for event in events {
            let mut ended = None;
            match &event {
                QueueEvent::Acked { id: Some(id), .. }
                | QueueEvent::Expired { id, .. }
                | QueueEvent::Dropped { id, .. } => {
                    if let Some(entry) = self.entries.remove(id) {
                        self.remove(entry);
                        ended = Some(entry);
                    }
                }
                QueueEvent::Sent {
                    message,
                    id,
                    awaiting_ack: false,
                    link,
                    ..
                } => {
                    if let Some(entry) = self.entries.remove(id) {
                        self.in_flight.push((*link, entry, message.clone()));
                        ended = Some(entry);
                    }
                }
                QueueEvent::Sent { id, .. } => ended = self.entries.get(id).copied(),
                _ => {}
            }
            out.push((event, ended));
        }
        self.sync_removals();
        out
    }

    /// Syncs the removals written since the last sync, if any. A sync that
    /// fails is tried again with the next removals; until then a power cut
    /// may bring their messages back (a restart sends them once more, as
    /// retransmissions their receivers suppress).
    fn sync_removals(&mut self) {
        if !self.removed_unsynced {
            return;
        }
        match self.journal.sync() {
            Ok(()) => self.removed_unsynced = false,
            Err(e) => tracing::warn!("{e}: the journal's removals are synced later"),
        }
    }

    /// Removes `entry` (its message left its queue for good) from the
    /// journal. A removal that cannot be written (a full disk) is kept and
    /// written again later ([`remove_again`](Self::remove_again)): the
    /// events go on all the same. Until it is written the journal still
    /// owes the message, and a restart would send it once more, as a
    /// retransmission its receiver suppresses.
    fn remove(&mut self, entry: EntryId) {
        match self.journal.remove(entry) {
            Ok(()) => self.removed_unsynced = true,
            Err(e) => {
                tracing::warn!("{e}: entry {entry} is removed once it can be written");
                self.unremoved.push(entry);
            }
        }
    }

    /// Writes again the removals that could not be written.
    fn remove_again(&mut self) {
        if self.unremoved.is_empty() {
            return;
        }
        let mut kept = Vec::new();
        for entry in std::mem::take(&mut self.unremoved) {
            match self.journal.remove(entry) {
                Ok(()) => self.removed_unsynced = true,
                Err(_) => kept.push(entry),
            }
        }
        if kept.is_empty() {
            tracing::info!("the journal's removals that waited are written");
        }
        self.unremoved = kept;
    }

    /// Settles the messages sent without ack in the transmission under way
    /// on link `link` (those of the other links wait for their own
    /// outcome): `went_out` removes them from the journal (synced, as
    /// [`events`](Self::events) does); otherwise (the
    /// driver failed to send) they are queued again with their original age.
    /// Returns how many were queued again.
    pub fn transmitted(&mut self, link: queue::LinkIndex, went_out: bool) -> usize {
        let (in_flight, others) = std::mem::take(&mut self.in_flight)
            .into_iter()
            .partition(|(l, _, _)| *l == link);
        self.in_flight = others;
        let mut requeued = 0;
        for (_, entry, message) in in_flight {
            if went_out {
                self.remove(entry);
                continue;
            }
            // The bytes the journal keeps: the message is not encoded
            // again.
            let journaled = self.journal.get(entry);
            let options = PushOptions {
                created: journaled.map(|e| e.time),
                number: Some(entry),
                resent: true,
                encoded: journaled
                    .filter(|e| e.encoding == Encoding::Dccl)
                    .map(|e| e.message.clone()),
            };
            match self.queue.push(message, options) {
                Ok(Some(id)) => {
                    self.entries.insert(id, entry);
                    requeued += 1;
                }
                Ok(None) | Err(_) => self.remove(entry),
            }
        }
        self.sync_removals();
        requeued
    }
}

/// The message a journal entry holds, read with `codec` (its DCCL
/// encoding, or the protobuf encoding journals of earlier versions hold), or
/// why it cannot be read.
pub fn journaled_message(
    codec: &dccl::Codec,
    entry: &JournalEntry,
) -> Result<DynamicMessage, String> {
    match entry.encoding {
        Encoding::Dccl => {
            let message = codec
                .decode(&entry.message)
                .map_err(|e| format!("the journaled bytes do not decode: {e}"))?;
            let name = message.descriptor().full_name().to_string();
            if name != entry.message_name {
                return Err(format!(
                    "the journaled bytes decode as {name}: its DCCL id is now another type's"
                ));
            }
            Ok(message)
        }
        Encoding::Protobuf => {
            let desc = codec
                .descriptor(&entry.message_name)
                .ok_or_else(|| "the type is not loaded".to_string())?;
            DynamicMessage::decode(desc, entry.message.as_slice())
                .map_err(|e| format!("the journaled bytes do not parse: {e}"))
        }
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;
    use std::sync::Arc;

    use protos::goby::acomms::protobuf::{
        queued_message_entry::{Role, RoleType},
        QueueManagerConfig, QueuedMessageEntry,
    };
    use protos::goby::example::Command;
    use queue::ManualClock;

    use super::*;

    struct Scratch(PathBuf);

    impl Scratch {
        fn new(name: &str) -> Self {
            let dir =
                std::env::temp_dir().join(format!("goby-outbox-{}-{name}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }
        fn journal(&self) -> PathBuf {
            self.0.join("outbox.journal")
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn queue(ack: bool, clock: &ManualClock) -> QueueManager {
        let mut codec = dccl::Codec::new();
        codec.load_type::<Command>().unwrap();
        let config = QueueManagerConfig {
            modem_id: Some(1),
            message_entry: vec![QueuedMessageEntry {
                protobuf_name: "goby.example.Command".into(),
                ack: Some(ack),
                ttl: Some(100),
                role: vec![Role {
                    r#type: RoleType::DestinationId as i32,
                    field: Some("destination".into()),
                    ..Default::default()
                }],
                ..Default::default()
            }],
            ..Default::default()
        };
        QueueManager::with_clock(Arc::new(codec), &config, Arc::new(clock.clone())).unwrap()
    }

    fn command(destination: i32, note: &str) -> DynamicMessage {
        Command {
            destination,
            action: 1,
            note: Some(note.into()),
            ..Default::default()
        }
        .transcode_to_dynamic()
    }

    fn request(outbox: &mut Outbox) -> ModemTransmission {
        let mut tx = ModemTransmission {
            max_frame_bytes: Some(32),
            max_num_frames: Some(1),
            ..Default::default()
        };
        outbox.data_request(&mut tx, 0, &[]).unwrap();
        outbox.events();
        tx
    }

    fn notes(outbox: &Outbox, frame: &[u8]) -> Vec<String> {
        outbox
            .queue()
            .codec()
            .decode_all(frame)
            .unwrap()
            .iter()
            .map(|m| {
                m.get_field_by_name("note")
                    .unwrap()
                    .as_str()
                    .unwrap()
                    .to_string()
            })
            .collect()
    }

    #[test]
    fn accepted_messages_survive_a_restart_until_acknowledged() {
        let dir = Scratch::new("restart");
        let clock = ManualClock::at_seconds(1_000.0);
        {
            let (mut outbox, replay) = Outbox::open(queue(true, &clock), &dir.journal()).unwrap();
            assert_eq!(replay, OutboxReplay::default());
            for note in ["a", "b"] {
                assert!(matches!(
                    outbox.accept(command(2, note), None, None).unwrap(),
                    Accepted::Queued(_)
                ));
            }
            // To ourselves: delivered, not kept.
            assert_eq!(
                outbox.accept(command(1, "me"), None, None).unwrap(),
                Accepted::Delivered
            );
            clock.advance_seconds(1.0);
            let tx = request(&mut outbox);
            assert_eq!(notes(&outbox, &tx.frame[0]), ["b", "a"]);
            // The ack for that frame arrives: both leave the journal.
            let ack = ModemTransmission {
                src: Some(2),
                dest: Some(1),
                r#type: Some(2),
                acked_frame: vec![0],
                ..Default::default()
            };
            outbox.receive(&ack, 0);
            outbox.events();
            assert_eq!(outbox.owed(), 0);
            // Two more, sent but never acknowledged.
            outbox.accept(command(2, "c"), None, None).unwrap();
            outbox.accept(command(2, "d"), None, None).unwrap();
            clock.advance_seconds(1.0);
            let tx = request(&mut outbox);
            assert_eq!(notes(&outbox, &tx.frame[0]).len(), 2);
            assert_eq!(outbox.owed(), 2);
            // The process dies here (no clean shutdown).
        }
        let (outbox, replay) = Outbox::open(queue(true, &clock), &dir.journal()).unwrap();
        assert_eq!(replay.requeued, 2);
        assert!(replay.failed.is_empty());
        assert_eq!(outbox.queue().size("goby.example.Command").unwrap(), 2);
    }

    #[test]
    fn messages_without_ack_are_queued_again_when_the_transmission_fails() {
        let dir = Scratch::new("failed");
        let clock = ManualClock::at_seconds(1_000.0);
        let (mut outbox, _) = Outbox::open(queue(false, &clock), &dir.journal()).unwrap();
        outbox.accept(command(2, "x"), None, None).unwrap();
        clock.advance_seconds(1.0);
        let tx = request(&mut outbox);
        assert_eq!(notes(&outbox, &tx.frame[0]), ["x"]);
        assert_eq!(outbox.queue().size("goby.example.Command").unwrap(), 0);
        // Still owed until the driver says it went out.
        assert_eq!(outbox.owed(), 1);
        assert_eq!(outbox.transmitted(0, false), 1);
        assert_eq!(outbox.queue().size("goby.example.Command").unwrap(), 1);
        clock.advance_seconds(1.0);
        let tx = request(&mut outbox);
        assert_eq!(notes(&outbox, &tx.frame[0]), ["x"]);
        assert_eq!(outbox.transmitted(0, true), 0);
        assert_eq!(outbox.owed(), 0);
    }

    #[test]
    fn refused_and_expired_messages_leave_no_journal_entry() {
        let dir = Scratch::new("refused");
        let clock = ManualClock::at_seconds(1_000.0);
        let (mut outbox, _) = Outbox::open(queue(true, &clock), &dir.journal()).unwrap();
        let nav = protos::goby::example::NavigationReport::default().transcode_to_dynamic();
        assert!(matches!(
            outbox.accept(nav, None, None),
            Err(OutboxError::Queue(_))
        ));
        outbox.accept(command(2, "old"), None, None).unwrap();
        assert_eq!(outbox.owed(), 1);
        clock.advance_seconds(101.0);
        outbox.expire();
        let events = outbox.events();
        assert!(events
            .iter()
            .any(|(e, _)| matches!(e, QueueEvent::Expired { .. })));
        assert_eq!(outbox.owed(), 0);
        drop(outbox);
        let (_, replay) = Outbox::open(queue(true, &clock), &dir.journal()).unwrap();
        assert_eq!(replay.requeued, 0);
    }

    #[test]
    fn a_message_is_encoded_once_and_its_bytes_are_journaled_and_sent() {
        let dir = Scratch::new("encoded-once");
        let clock = ManualClock::at_seconds(1_000.0);
        let (mut outbox, _) = Outbox::open(queue(false, &clock), &dir.journal()).unwrap();
        // Bytes given with the message are what the journal keeps and the
        // queue sends: those of another note show it is not encoded again.
        let given = outbox.queue().codec().encode(&command(2, "given")).unwrap();
        let Accepted::Queued(entry) = outbox
            .accept(command(2, "other"), Some(given.clone()), None)
            .unwrap()
        else {
            panic!("not queued");
        };
        let journaled = outbox.journaled().find(|e| e.id == entry).unwrap();
        assert_eq!(
            (journaled.encoding, &journaled.message),
            (queue::Encoding::Dccl, &given)
        );
        clock.advance_seconds(1.0);
        let tx = request(&mut outbox);
        assert_eq!(notes(&outbox, &tx.frame[0]), ["given"]);
        // Bytes of another type are refused, and nothing is kept.
        let nav = protos::goby::example::NavigationReport::default().transcode_to_dynamic();
        assert!(outbox
            .accept(command(2, "x"), Some(vec![0xFF; 4]), None)
            .is_err());
        assert!(outbox.accept(nav, Some(given), None).is_err());
        assert_eq!(outbox.owed(), 1);
    }

    #[test]
    fn a_journal_of_protobuf_records_is_queued_again() {
        use prost::Message as _;
        let dir = Scratch::new("protobuf-journal");
        let clock = ManualClock::at_seconds(1_000.0);
        // A journal as earlier versions wrote it: magic GOBYJNL2, the
        // message's protobuf encoding in an accepted record (kind 1).
        let name = "goby.example.Command";
        let protobuf = Command {
            destination: 2,
            action: 1,
            note: Some("kept".into()),
            ..Default::default()
        }
        .encode_to_vec();
        let mut payload = vec![1u8];
        payload.extend_from_slice(&7u64.to_le_bytes());
        payload.extend_from_slice(&999_000_000i64.to_le_bytes());
        payload.extend_from_slice(&(name.len() as u16).to_le_bytes());
        payload.extend_from_slice(name.as_bytes());
        payload.extend_from_slice(&protobuf);
        let mut bytes = b"GOBYJNL2".to_vec();
        queue::journal::JOURNAL.frame_into(&mut bytes, &payload);
        std::fs::write(dir.journal(), &bytes).unwrap();
        let (mut outbox, replay) = Outbox::open(queue(true, &clock), &dir.journal()).unwrap();
        assert_eq!(replay.requeued, 1, "{replay:?}");
        clock.advance_seconds(1.0);
        let tx = request(&mut outbox);
        assert_eq!(notes(&outbox, &tx.frame[0]), ["kept"]);
    }

    #[test]
    fn a_sending_names_the_journal_id_the_client_was_given() {
        for ack in [true, false] {
            let dir = Scratch::new(&format!("sent-id-{ack}"));
            let clock = ManualClock::at_seconds(1_000.0);
            let (mut outbox, _) = Outbox::open(queue(ack, &clock), &dir.journal()).unwrap();
            let Accepted::Queued(entry) = outbox.accept(command(2, "s"), None, None).unwrap()
            else {
                panic!("not queued");
            };
            outbox.events();
            clock.advance_seconds(1.0);
            let mut tx = ModemTransmission {
                max_frame_bytes: Some(32),
                max_num_frames: Some(1),
                ..Default::default()
            };
            outbox.data_request(&mut tx, 0, &[]).unwrap();
            let sent: Vec<_> = outbox
                .events()
                .into_iter()
                .filter(|(e, _)| matches!(e, QueueEvent::Sent { .. }))
                .map(|(_, entry)| entry)
                .collect();
            assert_eq!(sent, [Some(entry)], "ack {ack}");
        }
    }
}
