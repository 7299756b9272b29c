//! An append-only journal of queued messages, so that nothing accepted for
//! sending is lost when the process stops, crashes or loses power.
//!
//! Every message accepted is appended (and synced to disk) as an *accepted*
//! record before the caller reports it accepted; when the message leaves its
//! queue for good (acknowledged, expired, dropped) a *removed* record follows.
//! On opening, the records are replayed: the accepted messages without a
//! removed record are the ones still owed.
//!
//! The file is a record log of the [`JOURNAL`] format (magic `GOBYJNLD`):
//! framing, CRC, replay and its faults, appends, rewrites and the payload
//! limit are described in [`goby_store::record_log`]. A payload is
//!
//! ```text
//! kind: u8 | id: u64 LE | (accepted only) time: i64 LE µs | name length: u16 LE | name | message bytes
//! ```
//!
//! with kind 3 for *accepted* (the message's DCCL encoding, the bytes the
//! queue sends: a message is encoded once, when it is accepted) and 2 for
//! *removed*. Kind 1, *accepted* with the message's protobuf encoding, is
//! what journals of the `GOBYJNL2` magic hold: such a journal is read as it
//! is and takes the current magic, so that a version that reads only kind 1
//! refuses it instead of dropping its kind-3 records. What the journal
//! adds:
//!
//! - a write that fails (full disk, I/O error) is undone and reported:
//!   nothing is accepted that is not in the file; while the undo itself
//!   fails, every new message is refused;
//! - ids are `u64` and never wrap: when they run out, messages are refused
//!   ([`JournalError::IdsExhausted`]). A message's id is its publication
//!   number on the wire (see [`crate::identity`]): ids go on from the last
//!   one given, across restarts and compactions, and a journal that has
//!   given none (new, or every record lost) starts from a random id
//!   (below 2^32, [`Journal::skip_ids_to`]);
//! - damage between good records is left in place (the file is never cut
//!   behind a good record) and skipped again at the next start.
//!
//! A removed record lost to damage makes its message owed again: it is sent
//! once more (a duplicate, never a loss). When removed records dominate, the
//! file is rewritten with the live records only. Journals of the first
//! format (`GOBYJNL1`: the same framing without sync words, replayed up to
//! the first bad record) are read and rewritten in this one.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::clock::Micros;
use goby_store::record_log::{self, Format, LogError, MemoryFile, RecordLog, FRAMING, MAX_PAYLOAD};

pub(crate) use goby_store::record_log::LogFile as JournalFile;

/// The journal's file format: a record log ([`goby_store::record_log`])
/// of magic `GOBYJNLD`. `GOBYJNL2` journals, which hold no DCCL records,
/// are read and take it (`D` is five bits from `2`: a version that reads
/// only `GOBYJNL2` refuses the file rather than take its magic for a
/// damaged header of its own).
pub const JOURNAL: Format = Format {
    name: "journal",
    magic: b"GOBYJNLD",
    sync: [0xA7, 0x47, 0x4A, 0x52],
    older: &[b"GOBYJNL2"],
};

/// First bytes of a journal of the first format (no sync words).
const MAGIC_V1: &[u8; 8] = b"GOBYJNL1";
/// Kind byte of an accepted record holding a protobuf encoding (journals
/// of the `GOBYJNL2` magic).
const KIND_ACCEPTED_PROTOBUF: u8 = 1;
/// Kind byte of a removed record.
const KIND_REMOVED: u8 = 2;
/// Kind byte of an accepted record holding a DCCL encoding.
const KIND_ACCEPTED_DCCL: u8 = 3;
/// The journal is compacted when it is larger than this and at least half
/// of it is dead.
const COMPACT_MIN_BYTES: u64 = 1024 * 1024;

/// Identifier of a journaled message, unique within its journal.
pub type EntryId = u64;

/// How a journaled message's bytes are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// DCCL, with the codec of the queue that sends it: the bytes the queue
    /// sends (what the journal writes).
    Dccl,
    /// Protobuf (what journals of earlier versions hold).
    Protobuf,
}

/// A message accepted for sending and not yet removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JournalEntry {
    /// Its identifier.
    pub id: EntryId,
    /// When it was accepted.
    pub time: Micros,
    /// Full name of its protobuf type.
    pub message_name: String,
    /// Its encoding, as [`encoding`](Self::encoding) says.
    pub message: Vec<u8>,
    /// How `message` is encoded.
    pub encoding: Encoding,
}

/// What opening a journal found.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Replay {
    /// Messages still owed, oldest first.
    pub entries: Vec<JournalEntry>,
    /// Bytes skipped or cut off: damaged records, a torn tail, a damaged
    /// header (0 for a clean file).
    pub discarded_bytes: u64,
}

/// Errors of the journal.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// The file could not be read or written.
    #[error("journal {path}: {source}")]
    Io {
        /// The journal file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a journal (its first bytes are not the magic string).
    #[error("{0} is not a goby journal (unknown header); refusing to overwrite it")]
    NotAJournal(PathBuf),
    /// A message name longer than a record can hold.
    #[error("message name of {0} bytes is too long for the journal")]
    NameTooLong(usize),
    /// A message too large for a record.
    #[error("message of {0} bytes is too large for the journal")]
    MessageTooLarge(usize),
    /// Every id up to `u64::MAX` was used; ids never wrap.
    #[error("journal {0}: message ids are exhausted; move the journal away to start again")]
    IdsExhausted(PathBuf),
}

impl JournalError {
    fn of(path: &Path, e: impl Into<LogError>) -> Self {
        match e.into() {
            LogError::Io(source) => Self::Io {
                path: path.to_path_buf(),
                source,
            },
            LogError::NotOurs(_) => Self::NotAJournal(path.to_path_buf()),
            LogError::TooLarge(n) => Self::MessageTooLarge(n),
        }
    }
}

/// An open journal file.
#[derive(Debug)]
pub struct Journal {
    log: RecordLog,
    /// Id of the next message; `None` once every id was used.
    next_id: Option<EntryId>,
    /// Live entries by id (kept for compaction).
    live: BTreeMap<EntryId, JournalEntry>,
    /// Bytes of live accepted records.
    live_bytes: u64,
}

impl Journal {
    /// Opens (or creates, mode 0600) the journal at `path` and replays it.
    pub fn open(path: impl AsRef<Path>) -> Result<(Self, Replay), JournalError> {
        let path = path.as_ref();
        let log =
            RecordLog::create_or_open(path, JOURNAL).map_err(|e| JournalError::of(path, e))?;
        Self::open_log(log)
    }

    /// Replays the journal held by `file` (named `path` in errors, and
    /// where compaction writes).
    pub(crate) fn open_with(
        path: impl AsRef<Path>,
        file: impl JournalFile + 'static,
    ) -> Result<(Self, Replay), JournalError> {
        Self::open_log(RecordLog::with_file(path, JOURNAL, file))
    }

    fn open_log(mut log: RecordLog) -> Result<(Self, Replay), JournalError> {
        let path = log.path().to_path_buf();
        let bytes = log.read_all().map_err(|e| JournalError::of(&path, e))?;
        let (records, discarded_bytes, legacy) = if bytes.starts_with(MAGIC_V1) {
            // The first format: records without sync words, replayed up to
            // the first bad one, then rewritten in this format.
            let mut records = Vec::new();
            let mut at = MAGIC_V1.len();
            while let Some(record) = record_log::unsynced_record_at(&bytes, at)
                .and_then(|(payload, next)| Some((parse_record(payload)?, next)))
            {
                records.push(record.0);
                at = record.1;
            }
            (records, (bytes.len() - at) as u64, true)
        } else {
            let replayed = log
                .replay(&bytes, parse_record)
                .map_err(|e| JournalError::of(&path, e))?;
            (replayed.records, replayed.discarded_bytes, false)
        };
        drop(bytes);

        let mut live = BTreeMap::new();
        let mut next_id = Some(0);
        for record in records {
            let id = match record {
                Record::Accepted(entry) => {
                    let id = entry.id;
                    live.insert(id, entry);
                    id
                }
                Record::Removed(id) => {
                    live.remove(&id);
                    id
                }
            };
            next_id = match (next_id, id.checked_add(1)) {
                (Some(n), Some(after)) => Some(n.max(after)),
                _ => None,
            };
        }
        let live_bytes = live.values().map(|e| accepted_size(e) as u64).sum();
        let mut journal = Self {
            log,
            next_id,
            live,
            live_bytes,
        };
        if legacy {
            journal.compact()?;
        }
        let replay = Replay {
            entries: journal.live.values().cloned().collect(),
            discarded_bytes,
        };
        Ok((journal, replay))
    }

    /// Path of the journal file.
    pub fn path(&self) -> &Path {
        self.log.path()
    }

    /// Number of messages still owed.
    pub fn len(&self) -> usize {
        self.live.len()
    }

    /// Whether no message is owed.
    pub fn is_empty(&self) -> bool {
        self.live.is_empty()
    }

    /// While the journal has given no id (it is new, or every record of
    /// it was lost), makes the next id `first`. A caller that uses ids as
    /// publication numbers on the wire (see [`crate::identity`]) starts
    /// such a journal at a random id, so that a data directory made anew
    /// does not give again the numbers of the last messages a receiver may
    /// remember. A journal that has given ids goes on from the last one
    /// (kept through compactions, even when nothing is owed): its numbers
    /// come in sequence, and a receiver takes none of them for one it
    /// remembers until the numbers wrap (`identity::NUMBERS`
    /// publications later). A jump to a random id at every start would
    /// give, once in so many starts, the number of a publication the
    /// receiver remembers: a deliberate repeat retransmitted under it
    /// would be taken for that one and dropped.
    pub fn skip_ids_to(&mut self, first: EntryId) {
        if self.next_id == Some(0) {
            self.next_id = Some(first);
        }
    }

    /// The id the next accepted message will get (`None`: every id was
    /// used).
    pub fn next_id(&self) -> Option<EntryId> {
        self.next_id
    }

    /// The message `id`, if still owed.
    pub fn get(&self, id: EntryId) -> Option<&JournalEntry> {
        self.live.get(&id)
    }

    /// The messages still owed, oldest first.
    pub fn entries(&self) -> impl Iterator<Item = &JournalEntry> {
        self.live.values()
    }

    /// Appends an accepted message (`message`: its DCCL encoding) and
    /// syncs it to disk; returns its id. When this returns `Ok`, the
    /// message survives a crash.
    pub fn accept(
        &mut self,
        message_name: &str,
        message: impl Into<Vec<u8>>,
        time: Micros,
    ) -> Result<EntryId, JournalError> {
        let id = self.accept_unsynced(message_name, message, time)?;
        self.sync()?;
        Ok(id)
    }

    /// Appends an accepted message (`message`: its DCCL encoding) without
    /// waiting for the disk; it
    /// survives a crash once a later [`sync`](Self::sync) (or a sync of a
    /// [`sync_handle`](Self::sync_handle)) returns. Lets a caller sync many
    /// messages at once, off its own thread. `message` is taken as it is
    /// when given as a `Vec` (a slice is copied).
    pub fn accept_unsynced(
        &mut self,
        message_name: &str,
        message: impl Into<Vec<u8>>,
        time: Micros,
    ) -> Result<EntryId, JournalError> {
        if message_name.len() > usize::from(u16::MAX) {
            return Err(JournalError::NameTooLong(message_name.len()));
        }
        let id = self
            .next_id
            .ok_or_else(|| JournalError::IdsExhausted(self.path().to_path_buf()))?;
        let entry = JournalEntry {
            id,
            time,
            message_name: message_name.to_string(),
            message: message.into(),
            encoding: Encoding::Dccl,
        };
        if accepted_size(&entry) - FRAMING > MAX_PAYLOAD {
            return Err(JournalError::MessageTooLarge(entry.message.len()));
        }
        let written = self
            .log
            .append_with(|out| write_accepted(out, &entry))
            .map_err(|e| JournalError::of(self.log.path(), e))?;
        self.next_id = id.checked_add(1);
        self.live_bytes += written;
        self.live.insert(id, entry);
        Ok(id)
    }

    /// Waits until everything appended so far is on disk.
    pub fn sync(&mut self) -> Result<(), JournalError> {
        self.log
            .sync()
            .map_err(|e| JournalError::of(self.log.path(), e))
    }

    /// A second handle on the journal file whose `sync_data` makes
    /// everything appended before the call durable (for syncing on another
    /// thread).
    pub fn sync_handle(&self) -> Result<goby_store::record_log::SyncHandle, JournalError> {
        self.log
            .sync_handle()
            .map_err(|e| JournalError::of(self.log.path(), e))
    }

    /// Records that a message left its queue for good (acknowledged,
    /// expired or dropped). Unknown ids are ignored. Not synced: if the
    /// record is lost in a crash, the message is sent once more after the
    /// restart (a duplicate, never a loss).
    pub fn remove(&mut self, id: EntryId) -> Result<(), JournalError> {
        let Some(entry) = self.live.get(&id) else {
            return Ok(());
        };
        let size = accepted_size(entry) as u64;
        // Written first: a removal that cannot be written (a full disk)
        // leaves the entry owed, here as in the file, to be removed again.
        self.log
            .append_with(|out| write_removed(out, id))
            .map_err(|e| JournalError::of(self.log.path(), e))?;
        self.live.remove(&id);
        self.live_bytes -= size;
        let len = self.log.file_len();
        if len > COMPACT_MIN_BYTES && self.live_bytes * 2 < len {
            self.compact()?;
        }
        Ok(())
    }

    /// Rewrites the file with the live records only.
    pub(crate) fn compact(&mut self) -> Result<(), JournalError> {
        // Keep the id sequence going across compactions even if the newest
        // entries were removed: a removed record of the last id preserves it.
        let last = match self.next_id {
            Some(next) => next.checked_sub(1),
            None => Some(EntryId::MAX),
        };
        let last_removed = last
            .filter(|last| !self.live.contains_key(last))
            .map(removed_payload);
        let payloads = self.live.values().map(accepted_payload).chain(last_removed);
        let rewritten = self.log.rewrite(payloads);
        rewritten.map_err(|e| JournalError::of(self.log.path(), e))
    }
}

/// One record of a journal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Record {
    /// A message was accepted for sending.
    Accepted(JournalEntry),
    /// The message of this id left its queue for good (acknowledged,
    /// expired, dropped, or sent without an ack wanted); the journal does
    /// not say which.
    Removed(EntryId),
}

/// Reads the bytes of a journal file as a history of records, without
/// touching any file (for reading a data directory after a mission).
/// `None` when the bytes are not a journal. A journal of the first format
/// (`GOBYJNL1`) is read up to its first bad record; the rest is one span
/// of damage. A compaction keeps only the messages still owed: accepted
/// records of messages that left before it are gone.
pub fn read_history(bytes: &[u8]) -> Option<record_log::Inspected<Record>> {
    if !bytes.starts_with(MAGIC_V1) {
        return JOURNAL.inspect(bytes, parse_record);
    }
    let mut records = Vec::new();
    let mut at = MAGIC_V1.len();
    while let Some((payload, next)) = record_log::unsynced_record_at(bytes, at) {
        let Some(record) = parse_record(payload) else {
            break;
        };
        records.push((at as u64, record));
        at = next;
    }
    let damage = (at < bytes.len())
        .then_some(record_log::Damage {
            offset: at as u64,
            len: (bytes.len() - at) as u64,
            tail: true,
        })
        .into_iter()
        .collect();
    Some(record_log::Inspected { records, damage })
}

fn accepted_size(entry: &JournalEntry) -> usize {
    FRAMING + 1 + 8 + 8 + 2 + entry.message_name.len() + entry.message.len()
}

fn accepted_payload(entry: &JournalEntry) -> Vec<u8> {
    let mut payload = Vec::with_capacity(accepted_size(entry) - FRAMING);
    write_accepted(&mut payload, entry);
    payload
}

/// Appends the payload of an accepted record to `out`.
fn write_accepted(out: &mut Vec<u8>, entry: &JournalEntry) {
    out.push(match entry.encoding {
        Encoding::Dccl => KIND_ACCEPTED_DCCL,
        Encoding::Protobuf => KIND_ACCEPTED_PROTOBUF,
    });
    out.extend_from_slice(&entry.id.to_le_bytes());
    out.extend_from_slice(&entry.time.to_le_bytes());
    out.extend_from_slice(&(entry.message_name.len() as u16).to_le_bytes());
    out.extend_from_slice(entry.message_name.as_bytes());
    out.extend_from_slice(&entry.message);
}

fn removed_payload(id: EntryId) -> Vec<u8> {
    let mut payload = Vec::with_capacity(9);
    write_removed(&mut payload, id);
    payload
}

/// Appends the payload of a removed record to `out`.
fn write_removed(out: &mut Vec<u8>, id: EntryId) {
    out.push(KIND_REMOVED);
    out.extend_from_slice(&id.to_le_bytes());
}

/// Little-endian integer of `N` bytes at `at`, if there are that many.
fn le<const N: usize>(bytes: &[u8], at: usize) -> Option<[u8; N]> {
    bytes.get(at..at.checked_add(N)?)?.try_into().ok()
}

/// The record a payload holds; `None` for one the journal did not write
/// (counted as damage).
fn parse_record(payload: &[u8]) -> Option<Record> {
    let (&kind, rest) = payload.split_first()?;
    let id = u64::from_le_bytes(le::<8>(rest, 0)?);
    match kind {
        KIND_REMOVED if rest.len() == 8 => Some(Record::Removed(id)),
        KIND_ACCEPTED_DCCL | KIND_ACCEPTED_PROTOBUF => {
            let time = i64::from_le_bytes(le::<8>(rest, 8)?);
            let name_len = u16::from_le_bytes(le::<2>(rest, 16)?) as usize;
            let name = rest.get(18..18 + name_len)?;
            let message_name = String::from_utf8(name.to_vec()).ok()?;
            let message = rest.get(18 + name_len..)?.to_vec();
            Some(Record::Accepted(JournalEntry {
                id,
                time,
                message_name,
                message,
                encoding: if kind == KIND_ACCEPTED_DCCL {
                    Encoding::Dccl
                } else {
                    Encoding::Protobuf
                },
            }))
        }
        _ => None,
    }
}

/// Replays journal bytes in memory, as opening a journal file does, without
/// touching any file: for fuzzing and inspection. `None` when the bytes are
/// not a journal.
pub fn replay_bytes(bytes: &[u8]) -> Option<Replay> {
    Journal::open_with("(memory)", MemoryFile::new(bytes.to_vec()))
        .ok()
        .map(|(_, replay)| replay)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs::{File, OpenOptions};
    use std::io;

    const MAGIC: &[u8; 8] = JOURNAL.magic;
    const SYNC: [u8; 4] = JOURNAL.sync;

    fn encode_accepted(entry: &JournalEntry) -> Vec<u8> {
        JOURNAL.frame(&accepted_payload(entry))
    }

    fn encode_removed(id: EntryId) -> Vec<u8> {
        JOURNAL.frame(&removed_payload(id))
    }

    struct TempDir(PathBuf);

    impl TempDir {
        fn new(name: &str) -> Self {
            let dir =
                std::env::temp_dir().join(format!("goby-journal-{}-{name}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).unwrap();
            Self(dir)
        }
        fn file(&self) -> PathBuf {
            self.0.join("queue.journal")
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn names(replay: &Replay) -> Vec<(EntryId, &str, &[u8])> {
        replay
            .entries
            .iter()
            .map(|e| (e.id, e.message_name.as_str(), e.message.as_slice()))
            .collect()
    }

    #[test]
    fn the_history_holds_every_record_with_its_offset_and_the_torn_tail() {
        let dir = TempDir::new("history");
        {
            let (mut j, _) = Journal::open(dir.file()).unwrap();
            j.accept("a.A", b"one", 10).unwrap();
            j.accept("b.B", b"two", 20).unwrap();
            j.remove(0).unwrap();
        }
        let mut bytes = std::fs::read(dir.file()).unwrap();
        let full = bytes.len() as u64;
        bytes.extend_from_slice(&encode_removed(1)[..5]);
        let history = read_history(&bytes).unwrap();
        let kinds: Vec<(u64, EntryId, bool)> = history
            .records
            .iter()
            .map(|(at, r)| match r {
                Record::Accepted(e) => (*at, e.id, true),
                Record::Removed(id) => (*at, *id, false),
            })
            .collect();
        let second = (MAGIC.len() + FRAMING + 1 + 8 + 8 + 2 + 3 + 3) as u64;
        let third = second + (FRAMING + 1 + 8 + 8 + 2 + 3 + 3) as u64;
        assert_eq!(kinds, [(8, 0, true), (second, 1, true), (third, 0, false)]);
        assert_eq!(
            history.damage,
            [record_log::Damage {
                offset: full,
                len: 5,
                tail: true
            }]
        );
        assert!(read_history(b"GOBYINB1").is_none());
    }

    #[test]
    fn accepted_and_not_removed_messages_are_replayed_in_order() {
        let dir = TempDir::new("replay");
        {
            let (mut j, replay) = Journal::open(dir.file()).unwrap();
            assert!(replay.entries.is_empty());
            assert_eq!(j.accept("a.A", b"one", 10).unwrap(), 0);
            assert_eq!(j.accept("b.B", b"two", 20).unwrap(), 1);
            assert_eq!(j.accept("a.A", b"", 30).unwrap(), 2);
            j.remove(1).unwrap();
            j.remove(99).unwrap();
            assert_eq!(j.len(), 2);
        }
        let (mut j, replay) = Journal::open(dir.file()).unwrap();
        assert_eq!(replay.discarded_bytes, 0);
        assert_eq!(
            names(&replay),
            [(0, "a.A", &b"one"[..]), (2, "a.A", &b""[..])]
        );
        assert_eq!(replay.entries[1].time, 30);
        // Ids keep growing after a reopen.
        assert_eq!(j.accept("c.C", b"three", 40).unwrap(), 3);
    }

    #[test]
    fn a_torn_last_record_is_dropped_and_the_rest_kept() {
        let dir = TempDir::new("torn");
        {
            let (mut j, _) = Journal::open(dir.file()).unwrap();
            j.accept("a.A", b"kept", 1).unwrap();
            j.accept("a.A", b"torn away", 2).unwrap();
        }
        let full = std::fs::read(dir.file()).unwrap();
        // Every cut inside the last record loses that record only.
        let second_start = MAGIC.len() + FRAMING + 1 + 8 + 8 + 2 + 3 + 4;
        for cut in second_start..full.len() {
            std::fs::write(dir.file(), &full[..cut]).unwrap();
            let (_, replay) = Journal::open(dir.file()).unwrap();
            assert_eq!(names(&replay), [(0, "a.A", &b"kept"[..])], "cut at {cut}");
            assert_eq!(replay.discarded_bytes, (cut - second_start) as u64);
            // The damaged tail was truncated away.
            assert_eq!(
                std::fs::metadata(dir.file()).unwrap().len(),
                second_start as u64
            );
        }
    }

    #[test]
    fn a_damaged_record_is_never_replayed_as_garbage() {
        let dir = TempDir::new("flip");
        {
            let (mut j, _) = Journal::open(dir.file()).unwrap();
            j.accept("a.A", b"first", 1).unwrap();
            j.accept("a.A", b"second", 2).unwrap();
        }
        let full = std::fs::read(dir.file()).unwrap();
        let second_start = MAGIC.len() + FRAMING + 1 + 8 + 8 + 2 + 3 + 5;
        for at in second_start..full.len() {
            let mut bytes = full.clone();
            bytes[at] ^= 0x10;
            std::fs::write(dir.file(), &bytes).unwrap();
            let (_, replay) = Journal::open(dir.file()).unwrap();
            assert_eq!(names(&replay), [(0, "a.A", &b"first"[..])], "flip at {at}");
        }
    }

    #[test]
    fn a_file_that_is_not_a_journal_is_left_alone() {
        let dir = TempDir::new("foreign");
        std::fs::write(dir.file(), b"important notes").unwrap();
        let err = Journal::open(dir.file()).unwrap_err();
        assert!(matches!(err, JournalError::NotAJournal(_)), "{err}");
        assert_eq!(std::fs::read(dir.file()).unwrap(), b"important notes");
    }

    #[test]
    fn a_removal_that_cannot_be_written_leaves_the_entry_owed_to_be_removed_again() {
        let dir = TempDir::new("full");
        let (mut j, _) = Journal::open(dir.file()).unwrap();
        let id = j.accept("a.A", b"one", 1).unwrap();
        goby_store::space::mark_full(&dir.0);
        let refused = j.remove(id);
        goby_store::space::mark_free(&dir.0);
        let e = refused.unwrap_err();
        assert!(e.to_string().contains("no space left"), "{e}");
        assert_eq!(j.len(), 1, "still owed, here as in the file");
        j.remove(id).unwrap();
        assert_eq!(j.len(), 0);
        drop(j);
        let (_, replay) = Journal::open(dir.file()).unwrap();
        assert!(replay.entries.is_empty(), "removed in the file");
    }

    #[test]
    fn ids_start_at_random_in_a_new_journal_only_and_go_on_across_restarts() {
        let dir = TempDir::new("numbers");
        {
            let (mut j, _) = Journal::open(dir.file()).unwrap();
            j.skip_ids_to(5_000);
            let id = j.accept("a.A", b"one", 1).unwrap();
            assert_eq!(id, 5_000);
            j.remove(id).unwrap();
        }
        // Owing nothing, and compacted empty: it goes on from its last id,
        // whatever the new start drawn.
        let (mut j, _) = Journal::open(dir.file()).unwrap();
        j.compact().unwrap();
        drop(j);
        for drawn in [9_999, 17] {
            let (mut j, replay) = Journal::open(dir.file()).unwrap();
            assert!(replay.entries.is_empty());
            j.skip_ids_to(drawn);
            assert_eq!(j.next_id(), Some(5_001), "drawn {drawn}");
        }
    }

    #[test]
    fn compaction_keeps_live_entries_and_the_id_sequence() {
        let dir = TempDir::new("compact");
        let big = vec![7u8; 64 * 1024];
        {
            let (mut j, _) = Journal::open(dir.file()).unwrap();
            for i in 0..40 {
                let id = j.accept("a.A", big.as_slice(), i).unwrap();
                if i % 4 != 0 {
                    j.remove(id).unwrap();
                }
            }
            let id = j.accept("a.A", b"last", 99).unwrap();
            j.remove(id).unwrap();
            j.compact().unwrap();
            assert!(std::fs::metadata(dir.file()).unwrap().len() < 12 * 64 * 1024);
        }
        let (mut j, replay) = Journal::open(dir.file()).unwrap();
        let ids: Vec<EntryId> = replay.entries.iter().map(|e| e.id).collect();
        assert_eq!(ids, (0..40).step_by(4).collect::<Vec<_>>());
        assert!(replay.entries.iter().all(|e| e.message == big));
        assert_eq!(j.accept("a.A", b"next", 100).unwrap(), 41);
    }

    #[test]
    fn a_journal_of_protobuf_records_is_read_and_its_records_kept_as_they_are() {
        let dir = TempDir::new("protobuf");
        // A journal of the earlier magic: two messages in protobuf
        // (kind 1), one of them removed.
        let old = |id: EntryId, message: &[u8]| JournalEntry {
            id,
            time: 10 + id as i64,
            message_name: "a.A".into(),
            message: message.to_vec(),
            encoding: Encoding::Protobuf,
        };
        let mut bytes = b"GOBYJNL2".to_vec();
        bytes.extend(encode_accepted(&old(0, b"pb-0")));
        bytes.extend(encode_accepted(&old(1, b"pb-1")));
        bytes.extend(encode_removed(0));
        assert_eq!(bytes[8 + FRAMING], 1, "kind 1");
        std::fs::write(dir.file(), &bytes).unwrap();
        {
            let (mut j, replay) = Journal::open(dir.file()).unwrap();
            assert_eq!(replay.entries, [old(1, b"pb-1")]);
            assert_eq!(replay.discarded_bytes, 0);
            // New messages are journaled in DCCL.
            assert_eq!(j.accept("a.A", b"dccl-2", 20).unwrap(), 2);
            assert_eq!(j.get(2).unwrap().encoding, Encoding::Dccl);
            j.compact().unwrap();
        }
        let file = std::fs::read(dir.file()).unwrap();
        assert!(file.starts_with(JOURNAL.magic), "the current magic");
        let (_, replay) = Journal::open(dir.file()).unwrap();
        let encodings: Vec<_> = replay
            .entries
            .iter()
            .map(|e| (e.id, e.encoding, e.message.clone()))
            .collect();
        assert_eq!(
            encodings,
            [
                (1, Encoding::Protobuf, b"pb-1".to_vec()),
                (2, Encoding::Dccl, b"dccl-2".to_vec())
            ]
        );
    }

    /// The records of a small journal, written by hand: the file's bytes
    /// and the byte range of each record.
    fn small_journal() -> (Vec<u8>, Vec<(std::ops::Range<usize>, Record)>) {
        let entry = |id, message: &[u8]| JournalEntry {
            id,
            time: 100 + id as i64,
            message_name: "a.A".into(),
            message: message.to_vec(),
            encoding: Encoding::Dccl,
        };
        let records = vec![
            Record::Accepted(entry(0, b"one")),
            Record::Accepted(entry(1, b"two")),
            Record::Removed(0),
            Record::Accepted(entry(2, b"three")),
        ];
        let mut bytes = MAGIC.to_vec();
        let mut ranges = Vec::new();
        for r in records {
            let encoded = match &r {
                Record::Accepted(e) => encode_accepted(e),
                Record::Removed(id) => encode_removed(*id),
            };
            let start = bytes.len();
            bytes.extend_from_slice(&encoded);
            ranges.push((start..bytes.len(), r));
        }
        (bytes, ranges)
    }

    /// Entries owed after applying `records`, in id order.
    fn owed<'a>(records: impl Iterator<Item = &'a Record>) -> Vec<JournalEntry> {
        let mut live = BTreeMap::new();
        for r in records {
            match r {
                Record::Accepted(e) => {
                    live.insert(e.id, e.clone());
                }
                Record::Removed(id) => {
                    live.remove(id);
                }
            }
        }
        live.into_values().collect()
    }

    #[test]
    fn a_flipped_bit_anywhere_costs_at_most_its_own_record() {
        let dir = TempDir::new("every-bit");
        let (bytes, records) = small_journal();
        std::fs::write(dir.file(), &bytes).unwrap();
        let (_, clean) = Journal::open(dir.file()).unwrap();
        assert_eq!(clean.entries, owed(records.iter().map(|(_, r)| r)));
        assert_eq!(clean.entries.len(), 2);
        for at in 0..bytes.len() {
            for bit in 0..8 {
                let mut damaged = bytes.clone();
                damaged[at] ^= 1 << bit;
                std::fs::write(dir.file(), &damaged).unwrap();
                let hit = records.iter().position(|(range, _)| range.contains(&at));
                let expected = owed(
                    records
                        .iter()
                        .enumerate()
                        .filter(|(i, _)| Some(*i) != hit)
                        .map(|(_, (_, r))| r),
                );
                let what = format!("bit {bit} of byte {at} (record {hit:?})");
                let (mut j, replay) =
                    Journal::open(dir.file()).unwrap_or_else(|e| panic!("{what}: not opened: {e}"));
                assert_eq!(replay.entries, expected, "{what}");
                assert!(replay.discarded_bytes > 0, "{what}: damage not reported");
                // What was kept stays kept, and new records are found after
                // the damage.
                j.accept_unsynced("b.B", b"after", 999).unwrap();
                drop(j);
                let (_, again) = Journal::open(dir.file()).unwrap();
                let mut kept: Vec<&[u8]> =
                    again.entries.iter().map(|e| e.message.as_slice()).collect();
                assert_eq!(kept.pop(), Some(&b"after"[..]), "{what}");
                let before: Vec<&[u8]> = expected.iter().map(|e| e.message.as_slice()).collect();
                assert_eq!(kept, before, "{what}");
                let ids: std::collections::BTreeSet<EntryId> =
                    again.entries.iter().map(|e| e.id).collect();
                assert_eq!(ids.len(), again.entries.len(), "{what}: an id reused");
            }
        }
    }

    #[test]
    fn a_partial_record_between_good_ones_is_skipped_exactly() {
        let dir = TempDir::new("partial");
        let (bytes, records) = small_journal();
        // The second record half written (the process died mid-write, the
        // next run appended after it).
        let second = records[1].0.clone();
        let cut = second.start + second.len() / 2;
        let mut file = bytes[..cut].to_vec();
        file.extend_from_slice(&bytes[second.end..]);
        std::fs::write(dir.file(), &file).unwrap();
        let (_, replay) = Journal::open(dir.file()).unwrap();
        let expected = owed(
            records
                .iter()
                .enumerate()
                .filter(|(i, _)| *i != 1)
                .map(|(_, (_, r))| r),
        );
        assert_eq!(replay.entries, expected);
        assert_eq!(replay.discarded_bytes, (cut - second.start) as u64);
        // Nothing behind the good records was cut.
        assert_eq!(std::fs::read(dir.file()).unwrap(), file);
    }

    /// A journal file on a disk with `room` bytes: a write past it writes
    /// what fits and fails; cutting the file back fails while
    /// `fail_set_len`.
    #[derive(Debug)]
    struct SmallDisk {
        file: File,
        faults: std::sync::Arc<std::sync::Mutex<(u64, bool)>>,
    }

    impl JournalFile for SmallDisk {
        fn read_all(&mut self) -> io::Result<Vec<u8>> {
            self.file.read_all()
        }
        fn write_at(&mut self, offset: u64, bytes: &[u8]) -> io::Result<()> {
            let room = self.faults.lock().unwrap().0;
            let fits = room.saturating_sub(offset).min(bytes.len() as u64) as usize;
            JournalFile::write_at(&mut self.file, offset, &bytes[..fits])?;
            if fits < bytes.len() {
                return Err(io::Error::other("no space left on device"));
            }
            Ok(())
        }
        fn set_len(&mut self, len: u64) -> io::Result<()> {
            if self.faults.lock().unwrap().1 {
                return Err(io::Error::other("I/O error"));
            }
            JournalFile::set_len(&mut self.file, len)
        }
        fn sync(&mut self) -> io::Result<()> {
            self.file.sync()
        }
        fn sync_handle(&self) -> io::Result<File> {
            self.file.sync_handle()
        }
        fn reopen(&mut self, path: &Path) -> io::Result<()> {
            self.file.reopen(path)
        }
    }

    #[test]
    fn a_failed_write_is_refused_and_leaves_no_partial_record() {
        let dir = TempDir::new("full-disk");
        let faults = std::sync::Arc::new(std::sync::Mutex::new((u64::MAX, false)));
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(dir.file())
            .unwrap();
        let disk = SmallDisk {
            file,
            faults: faults.clone(),
        };
        let (mut j, _) = Journal::open_with(dir.file(), disk).unwrap();
        assert_eq!(j.accept("a.A", b"first", 1).unwrap(), 0);
        let size = || std::fs::metadata(dir.file()).unwrap().len();
        let before = size();
        // The disk fills up: the record does not fit.
        faults.lock().unwrap().0 = before + 10;
        let err = j.accept("a.A", b"does not fit", 2).unwrap_err();
        assert!(err.to_string().contains("no space left"), "{err}");
        assert_eq!(size(), before, "a partial record was left behind");
        assert_eq!(j.len(), 1);
        // Cutting back fails too: the partial record stays, and every new
        // message is refused until the journal is whole again.
        *faults.lock().unwrap() = (before + 10, true);
        j.accept("a.A", b"does not fit", 3).unwrap_err();
        assert_eq!(size(), before + 10);
        faults.lock().unwrap().0 = u64::MAX;
        j.accept("a.A", b"refused", 4).unwrap_err();
        j.remove(0).unwrap_err();
        // Room again: the partial record goes, appending resumes.
        faults.lock().unwrap().1 = false;
        assert_eq!(j.accept("a.A", b"second", 5).unwrap(), 1);
        drop(j);
        let (_, replay) = Journal::open(dir.file()).unwrap();
        assert_eq!(replay.discarded_bytes, 0);
        // The removal of 0 was refused: 0 is owed again after a restart (a
        // duplicate, never a loss).
        assert_eq!(
            names(&replay),
            [(0, "a.A", &b"first"[..]), (1, "a.A", &b"second"[..])]
        );
    }

    #[test]
    fn ids_never_wrap() {
        let dir = TempDir::new("ids");
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&encode_removed(u64::MAX - 1));
        std::fs::write(dir.file(), &bytes).unwrap();
        let (mut j, _) = Journal::open(dir.file()).unwrap();
        assert_eq!(j.accept("a.A", b"last", 1).unwrap(), u64::MAX);
        let err = j.accept("a.A", b"one too many", 2).unwrap_err();
        assert!(matches!(err, JournalError::IdsExhausted(_)), "{err}");
        drop(j);
        // Still exhausted after a restart, and after a compaction.
        let (mut j, replay) = Journal::open(dir.file()).unwrap();
        assert_eq!(replay.entries.len(), 1);
        j.remove(u64::MAX).unwrap();
        j.compact().unwrap();
        assert!(matches!(
            j.accept("a.A", b"x", 3),
            Err(JournalError::IdsExhausted(_))
        ));
        drop(j);
        let (mut j, _) = Journal::open(dir.file()).unwrap();
        assert!(matches!(
            j.accept("a.A", b"x", 3),
            Err(JournalError::IdsExhausted(_))
        ));
    }

    #[test]
    fn a_journal_of_the_first_format_is_read_and_rewritten() {
        let dir = TempDir::new("v1");
        let (bytes, records) = small_journal();
        // The first format: the same records without their sync words.
        let mut v1 = MAGIC_V1.to_vec();
        for (range, _) in &records {
            v1.extend_from_slice(&bytes[range.start + SYNC.len()..range.end]);
        }
        std::fs::write(dir.file(), &v1).unwrap();
        let expected = owed(records.iter().map(|(_, r)| r));
        assert_eq!(replay_bytes(&v1).unwrap().entries, expected);
        let (mut j, replay) = Journal::open(dir.file()).unwrap();
        assert_eq!(replay.entries, expected);
        assert_eq!(j.accept("a.A", b"four", 5).unwrap(), 3);
        drop(j);
        assert!(std::fs::read(dir.file()).unwrap().starts_with(MAGIC));
        let (_, replay) = Journal::open(dir.file()).unwrap();
        assert_eq!(replay.entries.len(), 3);
    }

    #[test]
    fn skipped_bytes_before_a_torn_tail_are_counted_once() {
        // Found by the journal_replay fuzz target: garbage, then a sync word
        // with nothing after it.
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&[0x14, 0x03, 0xA7, 0x47, 0x4A, 0x52]);
        assert_eq!(replay_bytes(&bytes).unwrap().discarded_bytes, 6);
        // And skipped bytes between good records count as well.
        let (good, records) = small_journal();
        let mut bytes = good[..records[1].0.start].to_vec();
        bytes.extend_from_slice(&[1, 2, 3]);
        bytes.extend_from_slice(&good[records[1].0.start..]);
        bytes.extend_from_slice(&[0xA7, 0x47]);
        assert_eq!(replay_bytes(&bytes).unwrap().discarded_bytes, 5);
    }

    #[test]
    fn replay_in_memory_matches_the_file() {
        let (bytes, records) = small_journal();
        let replay = replay_bytes(&bytes).unwrap();
        assert_eq!(replay.entries, owed(records.iter().map(|(_, r)| r)));
        assert!(replay_bytes(b"not a journal at all").is_none());
    }

    #[cfg(unix)]
    #[test]
    fn a_new_journal_is_private() {
        use std::os::unix::fs::PermissionsExt;
        let dir = TempDir::new("mode");
        Journal::open(dir.file()).unwrap();
        let mode = std::fs::metadata(dir.file()).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600);
    }
}
