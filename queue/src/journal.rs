//! An append-only journal of queued messages, so that nothing accepted for
//! sending is lost when the process stops, crashes or loses power.
//!
//! Every message accepted is appended (and synced to disk) as an *accepted*
//! record before the caller reports it accepted; when the message leaves its
//! queue for good (acknowledged, expired, dropped) a *removed* record follows.
//! On opening, the records are replayed: the accepted messages without a
//! removed record are the ones still owed.
//!
//! The file starts with a magic string; each record is
//!
//! ```text
//! length: u32 LE (of the payload) | crc32: u32 LE (of length and payload) | payload
//! payload = kind: u8 | id: u64 LE | (accepted only) time: i64 LE µs | name length: u16 LE | name | message bytes
//! ```
//!
//! A record whose length runs past the end of the file or whose CRC-32 does
//! not match is where a write was torn (power lost mid-write) or the file was
//! damaged: it and everything after it are dropped (the file is truncated
//! there) and reported in [`Replay::discarded_bytes`], never replayed as
//! garbage. When removed records dominate, the file is rewritten with the
//! live records only (to a temporary file, synced, then renamed over the
//! journal).

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crc::{Crc, CRC_32_ISO_HDLC};

use crate::clock::Micros;

/// First bytes of a journal file (format version 1).
const MAGIC: &[u8; 8] = b"GOBYJNL1";
/// Kind byte of an accepted record.
const KIND_ACCEPTED: u8 = 1;
/// Kind byte of a removed record.
const KIND_REMOVED: u8 = 2;
/// Largest payload a record may have; a length above it marks damage.
const MAX_PAYLOAD: usize = 16 * 1024 * 1024;
/// Bytes of record framing (length and CRC).
const FRAMING: usize = 8;
/// The journal is compacted when it is larger than this and at least half
/// of it is dead.
const COMPACT_MIN_BYTES: u64 = 1024 * 1024;

const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Identifier of a journaled message, unique within its journal.
pub type EntryId = u64;

/// A message accepted for sending and not yet removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JournalEntry {
    /// Its identifier.
    pub id: EntryId,
    /// When it was accepted.
    pub time: Micros,
    /// Full name of its protobuf type.
    pub message_name: String,
    /// Its protobuf encoding.
    pub message: Vec<u8>,
}

/// What opening a journal found.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Replay {
    /// Messages still owed, oldest first.
    pub entries: Vec<JournalEntry>,
    /// Bytes dropped at the end of the file: a torn or damaged record and
    /// whatever followed it (0 for a clean file).
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
        source: io::Error,
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
}

/// An open journal file.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
    next_id: EntryId,
    /// Live entries by id (kept for compaction).
    live: BTreeMap<EntryId, JournalEntry>,
    /// Current file length.
    len: u64,
    /// Bytes of live accepted records.
    live_bytes: u64,
}

impl Journal {
    /// Opens (or creates) the journal at `path` and replays it.
    pub fn open(path: impl AsRef<Path>) -> Result<(Self, Replay), JournalError> {
        let path = path.as_ref().to_path_buf();
        let io_err = |source| JournalError::Io {
            path: path.clone(),
            source,
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io_err)?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io_err)?;

        let mut live = BTreeMap::new();
        let mut next_id = 0;
        let mut discarded_bytes = 0;
        let valid_len = if bytes.is_empty() {
            file.write_all(MAGIC).map_err(io_err)?;
            file.sync_all().map_err(io_err)?;
            sync_parent(&path).map_err(io_err)?;
            MAGIC.len()
        } else if bytes.len() < MAGIC.len() && MAGIC.starts_with(&bytes) {
            // Torn while writing the header: nothing was ever journaled.
            discarded_bytes = bytes.len() as u64;
            file.set_len(0).map_err(io_err)?;
            file.seek(SeekFrom::Start(0)).map_err(io_err)?;
            file.write_all(MAGIC).map_err(io_err)?;
            file.sync_all().map_err(io_err)?;
            MAGIC.len()
        } else if !bytes.starts_with(MAGIC) {
            return Err(JournalError::NotAJournal(path));
        } else {
            let mut at = MAGIC.len();
            while let Some((record, next)) = read_record(&bytes, at) {
                match record {
                    Record::Accepted(entry) => {
                        next_id = next_id.max(entry.id + 1);
                        live.insert(entry.id, entry);
                    }
                    Record::Removed(id) => {
                        next_id = next_id.max(id + 1);
                        live.remove(&id);
                    }
                }
                at = next;
            }
            if at < bytes.len() {
                discarded_bytes = (bytes.len() - at) as u64;
                file.set_len(at as u64).map_err(io_err)?;
                file.sync_all().map_err(io_err)?;
            }
            at
        };
        file.seek(SeekFrom::Start(valid_len as u64))
            .map_err(io_err)?;
        let live_bytes = live.values().map(|e| accepted_size(e) as u64).sum();
        let journal = Self {
            path,
            file,
            next_id,
            live,
            len: valid_len as u64,
            live_bytes,
        };
        let replay = Replay {
            entries: journal.live.values().cloned().collect(),
            discarded_bytes,
        };
        Ok((journal, replay))
    }

    /// Path of the journal file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of messages still owed.
    pub fn len(&self) -> usize {
        self.live.len()
    }

    /// Whether no message is owed.
    pub fn is_empty(&self) -> bool {
        self.live.is_empty()
    }

    /// The message `id`, if still owed.
    pub fn get(&self, id: EntryId) -> Option<&JournalEntry> {
        self.live.get(&id)
    }

    /// The messages still owed, oldest first.
    pub fn entries(&self) -> impl Iterator<Item = &JournalEntry> {
        self.live.values()
    }

    /// Appends an accepted message and syncs it to disk; returns its id.
    /// When this returns `Ok`, the message survives a crash.
    pub fn accept(
        &mut self,
        message_name: &str,
        message: &[u8],
        time: Micros,
    ) -> Result<EntryId, JournalError> {
        let id = self.accept_unsynced(message_name, message, time)?;
        self.sync()?;
        Ok(id)
    }

    /// Appends an accepted message without waiting for the disk; it
    /// survives a crash once a later [`sync`](Self::sync) (or a sync of a
    /// [`sync_handle`](Self::sync_handle)) returns. Lets a caller sync many
    /// messages at once, off its own thread.
    pub fn accept_unsynced(
        &mut self,
        message_name: &str,
        message: &[u8],
        time: Micros,
    ) -> Result<EntryId, JournalError> {
        if message_name.len() > usize::from(u16::MAX) {
            return Err(JournalError::NameTooLong(message_name.len()));
        }
        let entry = JournalEntry {
            id: self.next_id,
            time,
            message_name: message_name.to_string(),
            message: message.to_vec(),
        };
        if accepted_size(&entry) - FRAMING > MAX_PAYLOAD {
            return Err(JournalError::MessageTooLarge(message.len()));
        }
        let record = encode_accepted(&entry);
        self.append(&record)?;
        self.next_id += 1;
        self.live_bytes += record.len() as u64;
        let id = entry.id;
        self.live.insert(id, entry);
        Ok(id)
    }

    /// Waits until everything appended so far is on disk.
    pub fn sync(&mut self) -> Result<(), JournalError> {
        self.file.sync_data().map_err(|source| JournalError::Io {
            path: self.path.clone(),
            source,
        })
    }

    /// A second handle on the journal file whose `sync_data` makes
    /// everything appended before the call durable (for syncing on another
    /// thread).
    pub fn sync_handle(&self) -> Result<File, JournalError> {
        self.file.try_clone().map_err(|source| JournalError::Io {
            path: self.path.clone(),
            source,
        })
    }

    /// Records that a message left its queue for good (acknowledged,
    /// expired or dropped). Unknown ids are ignored. Not synced: if the
    /// record is lost in a crash, the message is sent once more after the
    /// restart (a duplicate, never a loss).
    pub fn remove(&mut self, id: EntryId) -> Result<(), JournalError> {
        let Some(entry) = self.live.remove(&id) else {
            return Ok(());
        };
        self.live_bytes -= accepted_size(&entry) as u64;
        self.append(&encode_removed(id))?;
        if self.len > COMPACT_MIN_BYTES && self.live_bytes * 2 < self.len {
            self.compact()?;
        }
        Ok(())
    }

    /// Rewrites the file with the live records only.
    pub fn compact(&mut self) -> Result<(), JournalError> {
        let io_err = |source| JournalError::Io {
            path: self.path.clone(),
            source,
        };
        let mut tmp_name = self.path.as_os_str().to_owned();
        tmp_name.push(".compact");
        let tmp_path = PathBuf::from(tmp_name);
        let mut bytes = MAGIC.to_vec();
        for entry in self.live.values() {
            bytes.extend_from_slice(&encode_accepted(entry));
        }
        // Keep the id sequence going across compactions even if the newest
        // entries were removed: a removed record of the last id preserves it.
        if let Some(last) = self.next_id.checked_sub(1) {
            if !self.live.contains_key(&last) {
                bytes.extend_from_slice(&encode_removed(last));
            }
        }
        let mut tmp = File::create(&tmp_path).map_err(io_err)?;
        tmp.write_all(&bytes).map_err(io_err)?;
        tmp.sync_all().map_err(io_err)?;
        drop(tmp);
        std::fs::rename(&tmp_path, &self.path).map_err(io_err)?;
        sync_parent(&self.path).map_err(io_err)?;
        self.file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(&self.path)
            .map_err(io_err)?;
        self.file.seek(SeekFrom::End(0)).map_err(io_err)?;
        self.len = bytes.len() as u64;
        Ok(())
    }

    fn append(&mut self, record: &[u8]) -> Result<(), JournalError> {
        let io_err = |source| JournalError::Io {
            path: self.path.clone(),
            source,
        };
        self.file.write_all(record).map_err(io_err)?;
        self.len += record.len() as u64;
        Ok(())
    }
}

/// Syncs the directory holding `path`, so that a created or renamed file
/// survives power loss.
fn sync_parent(path: &Path) -> io::Result<()> {
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => File::open(dir)?.sync_all(),
        _ => File::open(".")?.sync_all(),
    }
}

enum Record {
    Accepted(JournalEntry),
    Removed(EntryId),
}

fn frame(payload: &[u8]) -> Vec<u8> {
    let len = (payload.len() as u32).to_le_bytes();
    let mut digest = CRC32.digest();
    digest.update(&len);
    digest.update(payload);
    let mut out = Vec::with_capacity(FRAMING + payload.len());
    out.extend_from_slice(&len);
    out.extend_from_slice(&digest.finalize().to_le_bytes());
    out.extend_from_slice(payload);
    out
}

fn accepted_size(entry: &JournalEntry) -> usize {
    FRAMING + 1 + 8 + 8 + 2 + entry.message_name.len() + entry.message.len()
}

fn encode_accepted(entry: &JournalEntry) -> Vec<u8> {
    let mut payload = Vec::with_capacity(accepted_size(entry) - FRAMING);
    payload.push(KIND_ACCEPTED);
    payload.extend_from_slice(&entry.id.to_le_bytes());
    payload.extend_from_slice(&entry.time.to_le_bytes());
    payload.extend_from_slice(&(entry.message_name.len() as u16).to_le_bytes());
    payload.extend_from_slice(entry.message_name.as_bytes());
    payload.extend_from_slice(&entry.message);
    frame(&payload)
}

fn encode_removed(id: EntryId) -> Vec<u8> {
    let mut payload = Vec::with_capacity(9);
    payload.push(KIND_REMOVED);
    payload.extend_from_slice(&id.to_le_bytes());
    frame(&payload)
}

/// Little-endian integer of `N` bytes at `at`, if there are that many.
fn le<const N: usize>(bytes: &[u8], at: usize) -> Option<[u8; N]> {
    bytes.get(at..at.checked_add(N)?)?.try_into().ok()
}

/// The record at `at` and the offset after it; `None` at the end of the
/// file, or where the record is torn or damaged.
fn read_record(bytes: &[u8], at: usize) -> Option<(Record, usize)> {
    let len_bytes = le::<4>(bytes, at)?;
    let len = u32::from_le_bytes(len_bytes) as usize;
    if len > MAX_PAYLOAD {
        return None;
    }
    let crc = u32::from_le_bytes(le::<4>(bytes, at + 4)?);
    let start = at + FRAMING;
    let payload = bytes.get(start..start.checked_add(len)?)?;
    let mut digest = CRC32.digest();
    digest.update(&len_bytes);
    digest.update(payload);
    if digest.finalize() != crc {
        return None;
    }
    let next = start + len;
    let (&kind, rest) = payload.split_first()?;
    let id = u64::from_le_bytes(le::<8>(rest, 0)?);
    match kind {
        KIND_REMOVED if rest.len() == 8 => Some((Record::Removed(id), next)),
        KIND_ACCEPTED => {
            let time = i64::from_le_bytes(le::<8>(rest, 8)?);
            let name_len = u16::from_le_bytes(le::<2>(rest, 16)?) as usize;
            let name = rest.get(18..18 + name_len)?;
            let message_name = String::from_utf8(name.to_vec()).ok()?;
            let message = rest.get(18 + name_len..)?.to_vec();
            Some((
                Record::Accepted(JournalEntry {
                    id,
                    time,
                    message_name,
                    message,
                }),
                next,
            ))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn compaction_keeps_live_entries_and_the_id_sequence() {
        let dir = TempDir::new("compact");
        let big = vec![7u8; 64 * 1024];
        {
            let (mut j, _) = Journal::open(dir.file()).unwrap();
            for i in 0..40 {
                let id = j.accept("a.A", &big, i).unwrap();
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
}
