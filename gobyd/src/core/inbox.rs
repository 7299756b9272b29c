//! The receiver's inbox: every message received from the link is recorded
//! on disk, synced, *before* it is handed over to the clients and before
//! the driver acknowledges it, and marked once handed over.
//!
//! The order makes a kill at any moment harmless to the message:
//!
//! - killed before the record is synced: nothing was acknowledged, the
//!   sender still owes the message and sends it again;
//! - killed after the sync, before the hand-over: the next start hands the
//!   message over (it is in the inbox, unmarked), once;
//! - killed after the hand-over: the mark is written right after the
//!   hand-over with no wait in between; only a kill landing exactly there
//!   (or a power loss before the mark reached the disk: marks are not
//!   synced) hands the message over again at the next start, flagged
//!   `recovered` in the mission log.
//!
//! The inbox also holds what the duplicate filter ([`crate::core::dedup`])
//! remembers: the identity of every message recorded within the window
//! (`duplicate_window_seconds`), so a repeat is recognised across restarts.
//!
//! The file (`DATA_DIR/inbox.log`) is a record log of the [`INBOX`] format
//! (magic `GOBYINB1`): framing, CRC, replay and its faults, appends,
//! rewrites and the payload limit are described in [`goby_store::record_log`].
//! A payload is
//!
//! ```text
//! kind 1, received: seq u64 | time u64 µs | src i32 | dccl_id u32 | digest u64 | dest i32
//!                   | has_time u8 | role time i64 µs | DCCL bytes of the message
//! kind 2, handed:   seq u64
//! kind 3, seen:     time u64 µs | src i32 | dccl_id u32 | digest u64   (written by compaction)
//! ```
//!
//! (all integers little-endian, after the kind byte). A lost *handed*
//! record hands its message over again (flagged `recovered`); a lost
//! *received* record loses that message only if it was also acknowledged.
//! Whenever replay left damage between good records, or dead records
//! dominate, the file is rewritten with the live records only. The file
//! holds the messages in DCCL form (as the journal holds outgoing ones).

use std::collections::{BTreeMap, HashMap};
use std::io;
use std::path::Path;

use goby_store::record_log::{Format, Inspected, LogError, RecordLog, CRC32 as CRC};

/// The inbox's file format: a record log ([`goby_store::record_log`]) of
/// magic `GOBYINB1`.
pub const INBOX: Format = Format {
    name: "inbox",
    magic: b"GOBYINB1",
    sync: [0xA7, 0x49, 0x4E, 0x42],
    older: &[],
};

use crate::core::dedup::Identity;

const KIND_RECEIVED: u8 = 1;
const KIND_HANDED: u8 = 2;
const KIND_SEEN: u8 = 3;
/// Fixed part of a received record's payload (kind included).
const RECEIVED_HEADER: usize = 1 + 8 + 8 + 4 + 4 + 8 + 4 + 1 + 8;

/// A message received from the link, as the inbox keeps it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Incoming {
    /// Source, DCCL id and digest (the duplicate filter's key).
    pub identity: Identity,
    /// Destination from the type's role (0: broadcast).
    pub dest: i32,
    /// Time from the type's role, microseconds since the epoch.
    pub role_time: Option<i64>,
    /// The message's DCCL encoding.
    pub bytes: Vec<u8>,
}

/// A message recorded and not yet handed over.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InboxEntry {
    /// Its number in the inbox.
    pub seq: u64,
    /// When it was recorded, microseconds since the epoch.
    pub time: u64,
    /// The message.
    pub incoming: Incoming,
}

/// What opening the inbox found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Replay {
    /// Identities still within the duplicate window.
    pub remembered: usize,
    /// Messages recorded and never marked handed over.
    pub pending: usize,
    /// Bytes of damaged or torn records, dropped.
    pub discarded_bytes: usize,
}

/// The inbox file and what it holds.
#[derive(Debug)]
pub struct Inbox {
    log: RecordLog,
    /// Microseconds an identity is remembered.
    window: u64,
    seen: HashMap<Identity, u64>,
    pending: BTreeMap<u64, InboxEntry>,
    next_seq: u64,
    /// Records in the file, live or not.
    records: usize,
}

fn received_payload(entry: &InboxEntry) -> Vec<u8> {
    let m = &entry.incoming;
    let mut p = Vec::with_capacity(RECEIVED_HEADER + m.bytes.len());
    p.push(KIND_RECEIVED);
    p.extend_from_slice(&entry.seq.to_le_bytes());
    p.extend_from_slice(&entry.time.to_le_bytes());
    p.extend_from_slice(&m.identity.src.to_le_bytes());
    p.extend_from_slice(&m.identity.dccl_id.to_le_bytes());
    p.extend_from_slice(&m.identity.digest.to_le_bytes());
    p.extend_from_slice(&m.dest.to_le_bytes());
    p.push(u8::from(m.role_time.is_some()));
    p.extend_from_slice(&m.role_time.unwrap_or(0).to_le_bytes());
    p.extend_from_slice(&m.bytes);
    p
}

fn seen_payload(id: &Identity, time: u64) -> Vec<u8> {
    let mut p = Vec::with_capacity(25);
    p.push(KIND_SEEN);
    p.extend_from_slice(&time.to_le_bytes());
    p.extend_from_slice(&id.src.to_le_bytes());
    p.extend_from_slice(&id.dccl_id.to_le_bytes());
    p.extend_from_slice(&id.digest.to_le_bytes());
    p
}

/// A record's content.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Record {
    /// A message received from the link was recorded (before it was
    /// handed over and acknowledged).
    Received(InboxEntry),
    /// The message of this `seq` was handed over to the clients.
    Handed(u64),
    /// A message of this identity was seen at this time (µs since the
    /// epoch), for the duplicate filter (written by compaction).
    Seen(Identity, u64),
}

/// Every record an inbox file holds, read without touching the file: each
/// with its offset, then the spans replay skips or cuts off. `None` when
/// the bytes are not an inbox. A compaction keeps only the messages not
/// yet handed over, and the identities still within the duplicate window.
pub fn read_history(bytes: &[u8]) -> Option<Inspected<Record>> {
    INBOX.inspect(bytes, parse)
}

/// The record a payload holds; `None` for one the inbox did not write
/// (counted as damage).
fn parse(payload: &[u8]) -> Option<Record> {
    let u64_at = |at: usize| {
        payload
            .get(at..at + 8)
            .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
    };
    let u32_at = |at: usize| {
        payload
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
    };
    match *payload.first()? {
        KIND_RECEIVED if payload.len() >= RECEIVED_HEADER => {
            let identity = Identity {
                src: u32_at(17)? as i32,
                dccl_id: u32_at(21)?,
                digest: u64_at(25)?,
            };
            let has_time = payload[37] != 0;
            let role_time = u64_at(38)? as i64;
            Some(Record::Received(InboxEntry {
                seq: u64_at(1)?,
                time: u64_at(9)?,
                incoming: Incoming {
                    identity,
                    dest: u32_at(33)? as i32,
                    role_time: has_time.then_some(role_time),
                    bytes: payload[RECEIVED_HEADER..].to_vec(),
                },
            }))
        }
        KIND_HANDED if payload.len() == 9 => Some(Record::Handed(u64_at(1)?)),
        KIND_SEEN if payload.len() == 25 => Some(Record::Seen(
            Identity {
                src: u32_at(9)? as i32,
                dccl_id: u32_at(13)?,
                digest: u64_at(17)?,
            },
            u64_at(1)?,
        )),
        _ => None,
    }
}

/// The inbox's errors as I/O errors, naming the file.
fn inbox_error(path: &Path, e: LogError) -> io::Error {
    match e {
        LogError::NotOurs(_) => io::Error::new(
            io::ErrorKind::InvalidData,
            format!(
                "{} is not a gobyd inbox (it does not start with {})",
                path.display(),
                String::from_utf8_lossy(INBOX.magic)
            ),
        ),
        e => e.into(),
    }
}

impl Inbox {
    /// Opens (or creates, mode 0600) the inbox at `path`, remembering
    /// identities for `window_micros` from `now` (microseconds since the
    /// epoch; 0: no duplicate filter). A file that is not an inbox is
    /// refused.
    pub fn open(path: &Path, window_micros: u64, now: u64) -> io::Result<(Self, Replay)> {
        Self::open_log(RecordLog::create_or_open(path, INBOX)?, window_micros, now)
    }

    /// Opens the inbox held by `file` (named `path`, where rewrites go), as
    /// [`open`](Self::open) does: for fault injection, and for replaying
    /// bytes in memory ([`goby_store::record_log::MemoryFile`]).
    #[cfg(any(test, feature = "internals"))]
    pub fn open_with(
        path: &Path,
        file: impl goby_store::record_log::LogFile + 'static,
        window_micros: u64,
        now: u64,
    ) -> io::Result<(Self, Replay)> {
        Self::open_log(RecordLog::with_file(path, INBOX, file), window_micros, now)
    }

    fn open_log(mut log: RecordLog, window_micros: u64, now: u64) -> io::Result<(Self, Replay)> {
        let bytes = log.read_all()?;
        let replayed = log
            .replay(&bytes, parse)
            .map_err(|e| inbox_error(log.path(), e))?;
        drop(bytes);
        let mut seen = HashMap::new();
        let mut pending = BTreeMap::new();
        let mut next_seq = 0;
        let records = replayed.records.len();
        // An identity is remembered from the latest time any record gives
        // it, whatever their order (a rewrite orders records otherwise).
        let mut saw = |id: Identity, time: u64| {
            let t = seen.entry(id).or_insert(time);
            *t = (*t).max(time);
        };
        for record in replayed.records {
            match record {
                Record::Received(entry) => {
                    next_seq = next_seq.max(entry.seq.saturating_add(1));
                    saw(entry.incoming.identity, entry.time);
                    pending.insert(entry.seq, entry);
                }
                Record::Handed(seq) => {
                    pending.remove(&seq);
                }
                Record::Seen(id, time) => saw(id, time),
            }
        }
        seen.retain(|_, t| t.saturating_add(window_micros) > now);
        let mut inbox = Inbox {
            log,
            window: window_micros,
            seen,
            pending,
            next_seq,
            records,
        };
        // Compacted when it holds damage or dead records; a full disk (or
        // another failed write) leaves it as it is, whole and read again
        // the same way, for a later compaction: the daemon still starts.
        if replayed.rewrite_advised || inbox.records > inbox.live() {
            if let Err(e) = inbox.rewrite() {
                tracing::warn!("{e}: left as it is, to be compacted later");
            }
        }
        let replay = Replay {
            remembered: inbox.seen.len(),
            pending: inbox.pending.len(),
            discarded_bytes: replayed.discarded_bytes as usize,
        };
        Ok((inbox, replay))
    }

    /// Where the inbox lives.
    pub fn path(&self) -> &Path {
        self.log.path()
    }

    /// Whether a message of identity `id` was recorded within the window
    /// before `now`: a repeat, to suppress (and acknowledge).
    pub fn is_duplicate(&self, id: &Identity, now: u64) -> bool {
        self.seen
            .get(id)
            .is_some_and(|t| t.saturating_add(self.window) > now)
    }

    /// The identities remembered (within the window when the inbox was
    /// opened or last marked a hand-over) and when each was recorded, in no
    /// particular order.
    #[cfg(any(test, feature = "internals"))]
    pub fn remembered(&self) -> impl Iterator<Item = (&Identity, u64)> {
        self.seen.iter().map(|(id, t)| (id, *t))
    }

    /// Appends a received message (not synced: call [`sync`](Self::sync)
    /// before handing it over or acknowledging it) and remembers its
    /// identity; returns its number. A failed write is cut back out of the
    /// file.
    pub fn record(&mut self, incoming: Incoming, now: u64) -> io::Result<u64> {
        if self.next_seq == u64::MAX {
            return Err(io::Error::other(format!(
                "{}: message numbers are exhausted; move the inbox away to start again",
                self.path().display()
            )));
        }
        let entry = InboxEntry {
            seq: self.next_seq,
            time: now,
            incoming,
        };
        self.append(&received_payload(&entry))?;
        self.next_seq += 1;
        let t = self.seen.entry(entry.incoming.identity).or_insert(now);
        *t = (*t).max(now);
        self.pending.insert(entry.seq, entry);
        Ok(self.next_seq - 1)
    }

    /// Remembers `id`, received at `now`, in memory only: a message that
    /// could not be recorded (a full disk) and is handed over all the same,
    /// so that its retransmissions are known as such while this process
    /// runs (after a restart they are not: see [`crate::core::delivery`]).
    pub fn remember_unrecorded(&mut self, id: Identity, now: u64) {
        let t = self.seen.entry(id).or_insert(now);
        *t = (*t).max(now);
    }

    /// Remembers `id`, received at `time` and handed over already (a
    /// *seen* record, appended, not synced), unless it is past the window.
    pub fn remember(&mut self, id: Identity, time: u64, now: u64) -> io::Result<()> {
        if time.saturating_add(self.window) <= now || self.seen.contains_key(&id) {
            return Ok(());
        }
        self.append(&seen_payload(&id, time))?;
        self.seen.insert(id, time);
        Ok(())
    }

    /// Takes over the identities of a duplicate filter file of the previous
    /// format (`delivered.log`: records of 28 bytes, `time: u64 | src: i32 |
    /// dccl_id: u32 | digest: u64 | crc32: u32`, little-endian, the CRC of
    /// the 24 bytes before it; replay stops at the first bad record), syncs,
    /// and removes the old file. Returns how many were taken over.
    pub fn take_over_delivered_log(&mut self, old: &Path, now: u64) -> io::Result<usize> {
        let bytes = match std::fs::read(old) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
            Err(e) => return Err(e),
        };
        let before = self.seen.len();
        for record in bytes.chunks_exact(28) {
            let crc = u32::from_le_bytes(record[24..28].try_into().expect("4 bytes"));
            if CRC.checksum(&record[..24]) != crc {
                break;
            }
            let time = u64::from_le_bytes(record[0..8].try_into().expect("8 bytes"));
            let id = Identity {
                src: i32::from_le_bytes(record[8..12].try_into().expect("4 bytes")),
                dccl_id: u32::from_le_bytes(record[12..16].try_into().expect("4 bytes")),
                digest: u64::from_le_bytes(record[16..24].try_into().expect("8 bytes")),
            };
            self.remember(id, time, now)?;
        }
        self.sync()?;
        std::fs::remove_file(old)?;
        Ok(self.seen.len() - before)
    }

    /// Syncs the records appended so far to disk.
    pub fn sync(&mut self) -> io::Result<()> {
        self.log.sync()
    }

    /// Marks message `seq` handed over (appended, not synced), forgets
    /// identities past the window, and compacts the file when most of its
    /// records are dead.
    pub fn handed(&mut self, seq: u64, now: u64) -> io::Result<()> {
        if self.pending.remove(&seq).is_none() {
            return Ok(());
        }
        let mut payload = vec![KIND_HANDED];
        payload.extend_from_slice(&seq.to_le_bytes());
        self.append(&payload)?;
        let window = self.window;
        self.seen.retain(|_, t| t.saturating_add(window) > now);
        if self.records > 2 * self.live() + 1024 {
            self.rewrite()?;
        }
        Ok(())
    }

    /// The messages recorded and not handed over, oldest first.
    pub fn pending(&self) -> Vec<InboxEntry> {
        self.pending.values().cloned().collect()
    }

    /// Records a compacted file would hold.
    fn live(&self) -> usize {
        let pending_ids = self.pending.len();
        self.seen.len().max(pending_ids)
    }

    /// Appends the record of `payload`; a failed write leaves no partial
    /// record behind (see [`RecordLog::append`]).
    fn append(&mut self, payload: &[u8]) -> io::Result<()> {
        self.log
            .append(payload)
            .map_err(|e| inbox_error(self.log.path(), e))?;
        self.records += 1;
        Ok(())
    }

    /// Writes the live records to a new file and puts it in place: the
    /// pending messages, then a *seen* record for each identity remembered
    /// from a later time than its pending messages give (or none).
    fn rewrite(&mut self) -> io::Result<()> {
        let mut pending_times: HashMap<Identity, u64> = HashMap::new();
        for e in self.pending.values() {
            let t = pending_times.entry(e.incoming.identity).or_insert(e.time);
            *t = (*t).max(e.time);
        }
        let mut seen: Vec<(&Identity, &u64)> = self
            .seen
            .iter()
            .filter(|(id, t)| pending_times.get(id) != Some(t))
            .collect();
        seen.sort_by_key(|(id, t)| (**t, id.src, id.dccl_id, id.digest));
        let payloads: Vec<Vec<u8>> = self
            .pending
            .values()
            .map(received_payload)
            .chain(seen.into_iter().map(|(id, time)| seen_payload(id, *time)))
            .collect();
        let records = payloads.len();
        let rewritten = self.log.rewrite(&payloads);
        rewritten.map_err(|e| inbox_error(self.log.path(), e))?;
        self.records = records;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use goby_store::record_log::FRAMING;
    use std::path::PathBuf;

    const MAGIC: &[u8; 8] = INBOX.magic;
    const SYNC: [u8; 4] = INBOX.sync;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("gobyd-inbox-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn incoming(src: i32, bytes: &[u8]) -> Incoming {
        Incoming {
            identity: Identity::of(src, 4, None, bytes),
            dest: 1,
            role_time: Some(-5),
            bytes: bytes.to_vec(),
        }
    }

    const WINDOW: u64 = 10_000_000;

    #[test]
    fn an_inbox_opens_on_a_full_disk_uncompacted_and_as_it_was() {
        let d = dir("full");
        let path = d.join("inbox.log");
        let (mut inbox, _) = Inbox::open(&path, WINDOW, 1_000).unwrap();
        let a = inbox.record(incoming(2, b"\x01\x02"), 1_000).unwrap();
        inbox.record(incoming(2, b"\x01\x03"), 1_000).unwrap();
        inbox.sync().unwrap();
        inbox.handed(a, 1_000).unwrap();
        drop(inbox);
        let before = std::fs::read(&path).unwrap();
        // Its dead record would have it compacted at the start; the disk
        // is full: it opens all the same, the file untouched.
        goby_store::space::mark_full(&d);
        let opened = Inbox::open(&path, WINDOW, 2_000);
        goby_store::space::mark_free(&d);
        let (inbox, replay) = opened.expect("opens on a full disk");
        assert_eq!((replay.pending, replay.remembered), (1, 2));
        assert_eq!(inbox.records, 3, "not compacted");
        assert_eq!(std::fs::read(&path).unwrap(), before);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_message_recorded_and_not_handed_over_is_pending_after_a_restart() {
        let d = dir("pending");
        let path = d.join("inbox.log");
        let (mut inbox, replay) = Inbox::open(&path, WINDOW, 1_000).unwrap();
        assert_eq!(replay, Replay::default());
        let a = inbox.record(incoming(2, b"\x01\x02"), 1_000).unwrap();
        let b = inbox.record(incoming(2, b"\x01\x03"), 1_000).unwrap();
        inbox.sync().unwrap();
        inbox.handed(a, 1_000).unwrap();
        drop(inbox); // killed before b was handed over

        let (mut inbox, replay) = Inbox::open(&path, WINDOW, 2_000).unwrap();
        assert_eq!((replay.pending, replay.remembered), (1, 2));
        let pending = inbox.pending();
        assert_eq!(pending.len(), 1);
        assert_eq!(pending[0].seq, b);
        assert_eq!(pending[0].incoming, incoming(2, b"\x01\x03"));
        // Both are known to the duplicate filter; another source is not.
        assert!(inbox.is_duplicate(&Identity::of(2, 4, None, b"\x01\x02"), 2_000));
        assert!(inbox.is_duplicate(&Identity::of(2, 4, None, b"\x01\x03"), 2_000));
        assert!(!inbox.is_duplicate(&Identity::of(3, 4, None, b"\x01\x02"), 2_000));
        inbox.handed(b, 2_000).unwrap();
        // New numbers do not reuse old ones.
        assert!(inbox.record(incoming(2, b"\x09"), 2_000).unwrap() > b);
        drop(inbox);
        let (inbox, _) = Inbox::open(&path, WINDOW, 3_000).unwrap();
        assert_eq!(inbox.pending().len(), 1);
        // Past the window nothing is a duplicate any more.
        assert!(!inbox.is_duplicate(&Identity::of(2, 4, None, b"\x01\x02"), 1_000 + WINDOW));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_torn_tail_is_cut_and_a_damaged_record_costs_only_itself() {
        let d = dir("damage");
        let path = d.join("inbox.log");
        let (mut inbox, _) = Inbox::open(&path, WINDOW, 1_000).unwrap();
        for i in 0..3u8 {
            inbox.record(incoming(2, &[i; 5]), 1_000).unwrap();
        }
        inbox.sync().unwrap();
        drop(inbox);
        let mut bytes = std::fs::read(&path).unwrap();
        let record = (bytes.len() - MAGIC.len()) / 3;
        // A bit flipped in the payload of the second record, and a torn
        // record appended.
        bytes[MAGIC.len() + record + FRAMING + 3] ^= 0x10;
        bytes.extend_from_slice(&SYNC);
        bytes.extend_from_slice(&[40, 0]);
        std::fs::write(&path, &bytes).unwrap();

        let (inbox, replay) = Inbox::open(&path, WINDOW, 2_000).unwrap();
        assert_eq!(replay.pending, 2);
        assert_eq!(replay.discarded_bytes, record + 6);
        let kept: Vec<Vec<u8>> = inbox
            .pending()
            .into_iter()
            .map(|e| e.incoming.bytes)
            .collect();
        assert_eq!(kept, vec![vec![0; 5], vec![2; 5]]);
        drop(inbox);
        // Rewritten: nothing is discarded the next time.
        let (_, replay) = Inbox::open(&path, WINDOW, 3_000).unwrap();
        assert_eq!((replay.pending, replay.discarded_bytes), (2, 0));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn compaction_keeps_pending_messages_and_identities_in_the_window() {
        let d = dir("compact");
        let path = d.join("inbox.log");
        // Identities are remembered for 100 µs; one message every 10 µs.
        let (mut inbox, _) = Inbox::open(&path, 100, 0).unwrap();
        for i in 0..3000u32 {
            let now = u64::from(i) * 10;
            let seq = inbox.record(incoming(2, &i.to_le_bytes()), now).unwrap();
            if i != 7 {
                inbox.handed(seq, now).unwrap();
            }
        }
        let size = std::fs::metadata(&path).unwrap().len();
        // Uncompacted: 3000 received and 2999 handed records, over 100 kB.
        assert!(size < 60_000, "{size}");
        drop(inbox);
        let (inbox, replay) = Inbox::open(&path, 100, 29_995).unwrap();
        assert_eq!(replay.pending, 1);
        assert_eq!(inbox.pending()[0].incoming.bytes, 7u32.to_le_bytes());
        assert!(inbox.is_duplicate(&Identity::of(2, 4, None, &2999u32.to_le_bytes()), 29_995));
        assert!(!inbox.is_duplicate(&Identity::of(2, 4, None, &2000u32.to_le_bytes()), 29_995));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn identities_of_the_previous_duplicate_filter_file_are_taken_over() {
        let d = dir("legacy");
        let old = d.join("delivered.log");
        let a = Identity::of(2, 4, None, b"a");
        let expired = Identity::of(2, 4, None, b"b");
        let mut bytes = Vec::new();
        for (id, time) in [(a, 15_000u64), (expired, 1)] {
            let start = bytes.len();
            bytes.extend_from_slice(&time.to_le_bytes());
            bytes.extend_from_slice(&id.src.to_le_bytes());
            bytes.extend_from_slice(&id.dccl_id.to_le_bytes());
            bytes.extend_from_slice(&id.digest.to_le_bytes());
            let crc = CRC.checksum(&bytes[start..]);
            bytes.extend_from_slice(&crc.to_le_bytes());
        }
        bytes.extend_from_slice(&[9, 9, 9]); // torn
        std::fs::write(&old, &bytes).unwrap();
        let path = d.join("inbox.log");
        let (mut inbox, _) = Inbox::open(&path, 10_000, 20_000).unwrap();
        assert_eq!(inbox.take_over_delivered_log(&old, 20_000).unwrap(), 1);
        assert!(!old.exists());
        drop(inbox);
        let (inbox, replay) = Inbox::open(&path, 10_000, 20_000).unwrap();
        assert_eq!(replay.remembered, 1);
        assert!(inbox.is_duplicate(&a, 20_000));
        assert!(!inbox.is_duplicate(&expired, 20_000));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_file_that_is_not_an_inbox_is_refused() {
        let d = dir("foreign");
        let path = d.join("inbox.log");
        std::fs::write(&path, b"hello, world\n").unwrap();
        let err = Inbox::open(&path, WINDOW, 0).unwrap_err().to_string();
        assert!(err.contains("not a gobyd inbox"), "{err}");
        assert_eq!(std::fs::read(&path).unwrap(), b"hello, world\n");
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A record framed by hand, as the format is documented.
    fn by_hand(payload: &[u8]) -> Vec<u8> {
        let mut out = vec![0xA7, 0x49, 0x4E, 0x42];
        out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
        let mut digest = CRC.digest();
        digest.update(&(payload.len() as u32).to_le_bytes());
        digest.update(payload);
        out.extend_from_slice(&digest.finalize().to_le_bytes());
        out.extend_from_slice(payload);
        out
    }

    #[test]
    fn a_file_in_the_documented_format_opens_and_is_written_alike() {
        let d = dir("format");
        let path = d.join("inbox.log");
        let a = incoming(2, b"\x01\x02");
        let seen = Identity::of(3, 4, None, b"x");
        let mut received = vec![KIND_RECEIVED];
        received.extend_from_slice(&0u64.to_le_bytes());
        received.extend_from_slice(&1_000u64.to_le_bytes());
        received.extend_from_slice(&a.identity.src.to_le_bytes());
        received.extend_from_slice(&a.identity.dccl_id.to_le_bytes());
        received.extend_from_slice(&a.identity.digest.to_le_bytes());
        received.extend_from_slice(&a.dest.to_le_bytes());
        received.push(1);
        received.extend_from_slice(&(-5i64).to_le_bytes());
        received.extend_from_slice(&a.bytes);
        let mut seen_record = vec![KIND_SEEN];
        seen_record.extend_from_slice(&900u64.to_le_bytes());
        seen_record.extend_from_slice(&seen.src.to_le_bytes());
        seen_record.extend_from_slice(&seen.dccl_id.to_le_bytes());
        seen_record.extend_from_slice(&seen.digest.to_le_bytes());
        let mut bytes = b"GOBYINB1".to_vec();
        bytes.extend_from_slice(&by_hand(&received));
        bytes.extend_from_slice(&by_hand(&seen_record));
        std::fs::write(&path, &bytes).unwrap();
        let (mut inbox, replay) = Inbox::open(&path, WINDOW, 2_000).unwrap();
        assert_eq!(
            (replay.pending, replay.remembered, replay.discarded_bytes),
            (1, 2, 0)
        );
        assert_eq!(inbox.pending()[0].incoming, a);
        assert!(inbox.is_duplicate(&seen, 2_000));
        // Left as it was, and what is appended is framed the same way.
        assert_eq!(std::fs::read(&path).unwrap(), bytes);
        inbox.handed(0, 2_000).unwrap();
        bytes.extend_from_slice(&by_hand(&[KIND_HANDED, 0, 0, 0, 0, 0, 0, 0, 0]));
        assert_eq!(std::fs::read(&path).unwrap(), bytes);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_damaged_header_is_put_right() {
        let d = dir("header");
        let path = d.join("inbox.log");
        let (mut inbox, _) = Inbox::open(&path, WINDOW, 1_000).unwrap();
        inbox.record(incoming(2, b"kept"), 1_000).unwrap();
        inbox.sync().unwrap();
        drop(inbox);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[2] ^= 0x04;
        std::fs::write(&path, &bytes).unwrap();
        let (inbox, replay) = Inbox::open(&path, WINDOW, 2_000).unwrap();
        assert_eq!((replay.pending, replay.discarded_bytes), (1, 8));
        assert_eq!(inbox.pending()[0].incoming.bytes, b"kept");
        assert!(std::fs::read(&path).unwrap().starts_with(MAGIC));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_message_over_the_record_limit_is_refused() {
        let d = dir("limit");
        let path = d.join("inbox.log");
        let (mut inbox, _) = Inbox::open(&path, WINDOW, 1_000).unwrap();
        let big = vec![0; goby_store::record_log::MAX_PAYLOAD];
        let err = inbox.record(incoming(2, &big), 1_000).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput, "{err}");
        assert!(inbox.pending().is_empty());
        assert_eq!(std::fs::read(&path).unwrap(), MAGIC);
        let _ = std::fs::remove_dir_all(&d);
    }

    /// Pending messages and remembered identities (sorted).
    fn live_records(inbox: &Inbox) -> (Vec<InboxEntry>, Vec<(Identity, u64)>) {
        let mut remembered: Vec<(Identity, u64)> =
            inbox.remembered().map(|(id, t)| (*id, t)).collect();
        remembered.sort_by_key(|(id, t)| (id.src, id.dccl_id, id.digest, *t));
        (inbox.pending(), remembered)
    }

    /// Opens `bytes` in memory; if an inbox, opens what it left again and
    /// checks it holds the same (as the inbox_replay fuzz target does).
    fn replays_stably(bytes: &[u8]) -> Option<Replay> {
        use goby_store::record_log::MemoryFile;
        let file = MemoryFile::new(bytes.to_vec());
        let memory = Path::new("(memory)");
        let (inbox, replay) = Inbox::open_with(memory, file.clone(), WINDOW, 5_000).ok()?;
        let first = live_records(&inbox);
        drop(inbox);
        let (inbox, again) =
            Inbox::open_with(memory, MemoryFile::new(file.contents()), WINDOW, 5_000).unwrap();
        assert_eq!(live_records(&inbox), first);
        assert_eq!(again.discarded_bytes, 0);
        Some(replay)
    }

    #[test]
    fn a_rewrite_keeps_what_replay_found_whatever_the_record_order() {
        let a = incoming(2, b"a");
        let entry = |seq, time| InboxEntry {
            seq,
            time,
            incoming: a.clone(),
        };
        let mut bytes = MAGIC.to_vec();
        // The same identity received twice and seen later, a handed record
        // before its message, and damage between them.
        bytes.extend_from_slice(&by_hand(&received_payload(&entry(3, 2_000))));
        bytes.extend_from_slice(&by_hand(&[KIND_HANDED, 1, 0, 0, 0, 0, 0, 0, 0]));
        bytes.extend_from_slice(&[1, 2, 3]);
        bytes.extend_from_slice(&by_hand(&received_payload(&entry(1, 1_000))));
        bytes.extend_from_slice(&by_hand(&seen_payload(&a.identity, 4_000)));
        bytes.extend_from_slice(&by_hand(&seen_payload(&a.identity, 3_000)));
        let replay = replays_stably(&bytes).unwrap();
        assert_eq!((replay.pending, replay.remembered), (2, 1));
        assert_eq!(replay.discarded_bytes, 3);
    }

    #[test]
    fn a_flipped_bit_anywhere_replays_stably() {
        let mut bytes = MAGIC.to_vec();
        for (seq, payload) in [b"one", b"two"].into_iter().enumerate() {
            let e = InboxEntry {
                seq: seq as u64,
                time: 1_000,
                incoming: incoming(2, payload),
            };
            bytes.extend_from_slice(&by_hand(&received_payload(&e)));
        }
        bytes.extend_from_slice(&by_hand(&[KIND_HANDED, 0, 0, 0, 0, 0, 0, 0, 0]));
        bytes.extend_from_slice(&by_hand(&seen_payload(
            &Identity::of(5, 4, None, b"s"),
            900,
        )));
        assert_eq!(replays_stably(&bytes).unwrap().discarded_bytes, 0);
        for at in 0..bytes.len() {
            for bit in 0..8 {
                let mut damaged = bytes.clone();
                damaged[at] ^= 1 << bit;
                let replay = replays_stably(&damaged);
                assert!(
                    replay.is_some_and(|r| r.discarded_bytes > 0),
                    "bit {bit} of {at}"
                );
            }
        }
        for cut in 0..bytes.len() {
            replays_stably(&bytes[..cut]).unwrap();
        }
    }
}
