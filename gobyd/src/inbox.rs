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
//! The inbox also holds what the duplicate filter ([`crate::dedup`])
//! remembers: the identity of every message recorded within the window
//! (`duplicate_window_seconds`), so a repeat is recognised across restarts.
//!
//! File format (`DATA_DIR/inbox.log`): the magic `GOBYINB1`, then records
//!
//! ```text
//! sync: 4 bytes A7 49 4E 42 | length: u32 LE (of the payload) | crc32: u32 LE (of length and payload) | payload
//! payload = kind 1, received: seq u64 | time u64 µs | src i32 | dccl_id u32 | digest u64 | dest i32
//!                             | has_time u8 | role time i64 µs | DCCL bytes of the message
//!         | kind 2, handed:   seq u64
//!         | kind 3, seen:     time u64 µs | src i32 | dccl_id u32 | digest u64   (written by compaction)
//! ```
//!
//! All integers little-endian. Faults cost the records they touch: a record
//! whose CRC-32 (ISO-HDLC) fails or whose length runs past the end is
//! skipped and replay goes on from the next sync word; bytes after the last
//! good record (a write torn by a crash) are dropped. A lost *handed* record
//! hands its message over again (flagged `recovered`); a lost *received*
//! record loses that message only if it was also acknowledged. Whenever
//! replay met damage, or dead records dominate, the file is rewritten with
//! the live records only (a temporary file, synced, renamed over it). Files
//! are created with mode 0600 and hold the messages in DCCL form (as the
//! journal holds outgoing ones).

use std::collections::{BTreeMap, HashMap};
use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use crc::{Crc, CRC_32_ISO_HDLC};

use crate::data_dir::private_file_options;
use crate::dedup::Identity;

const CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
/// First bytes of an inbox file.
const MAGIC: &[u8; 8] = b"GOBYINB1";
/// First bytes of every record.
const SYNC: [u8; 4] = [0xA7, 0x49, 0x4E, 0x42];
/// Bytes of record framing (sync word, length and CRC).
const FRAMING: usize = 12;
/// Largest payload a record may have; a length above it marks damage.
const MAX_PAYLOAD: usize = 1024 * 1024;
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
    path: PathBuf,
    file: File,
    /// Bytes of whole records in the file (a failed write is cut back to it).
    len: u64,
    /// Microseconds an identity is remembered.
    window: u64,
    seen: HashMap<Identity, u64>,
    pending: BTreeMap<u64, InboxEntry>,
    next_seq: u64,
    /// Records in the file, live or not.
    records: usize,
}

fn framed(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(FRAMING + payload.len());
    out.extend_from_slice(&SYNC);
    let len = (payload.len() as u32).to_le_bytes();
    out.extend_from_slice(&len);
    let mut digest = CRC.digest();
    digest.update(&len);
    digest.update(payload);
    out.extend_from_slice(&digest.finalize().to_le_bytes());
    out.extend_from_slice(payload);
    out
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
enum Record {
    Received(InboxEntry),
    Handed(u64),
    Seen(Identity, u64),
}

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

/// The record starting at `at`, with its length in the file, if whole and
/// sound.
fn record_at(bytes: &[u8], at: usize) -> Option<(Record, usize)> {
    let head = bytes.get(at..at + FRAMING)?;
    if head[..4] != SYNC {
        return None;
    }
    let len = u32::from_le_bytes(head[4..8].try_into().expect("4 bytes")) as usize;
    if len > MAX_PAYLOAD {
        return None;
    }
    let crc = u32::from_le_bytes(head[8..12].try_into().expect("4 bytes"));
    let payload = bytes.get(at + FRAMING..at + FRAMING + len)?;
    let mut digest = CRC.digest();
    digest.update(&head[4..8]);
    digest.update(payload);
    if digest.finalize() != crc {
        return None;
    }
    Some((parse(payload)?, FRAMING + len))
}

impl Inbox {
    /// Opens (or creates) the inbox at `path`, remembering identities for
    /// `window_micros` from `now` (microseconds since the epoch; 0: no
    /// duplicate filter). A file that is not an inbox is refused.
    pub fn open(path: &Path, window_micros: u64, now: u64) -> io::Result<(Self, Replay)> {
        let mut bytes = Vec::new();
        match File::open(path) {
            Ok(mut f) => {
                f.read_to_end(&mut bytes)?;
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        let mut discarded_bytes = 0;
        let mut needs_rewrite = bytes.len() < MAGIC.len();
        if bytes.len() >= MAGIC.len() {
            let flipped: u32 = bytes[..8]
                .iter()
                .zip(MAGIC)
                .map(|(a, b)| (a ^ b).count_ones())
                .sum();
            if flipped > 2 {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!(
                        "{} is not a gobyd inbox (it does not start with {})",
                        path.display(),
                        String::from_utf8_lossy(MAGIC)
                    ),
                ));
            }
            needs_rewrite |= flipped > 0;
        } else {
            discarded_bytes = bytes.len();
        }
        let mut seen = HashMap::new();
        let mut pending = BTreeMap::new();
        let mut next_seq = 0;
        let mut records = 0;
        let mut at = MAGIC.len().min(bytes.len());
        while at < bytes.len() {
            match record_at(&bytes, at) {
                Some((record, used)) => {
                    records += 1;
                    match record {
                        Record::Received(entry) => {
                            next_seq = next_seq.max(entry.seq + 1);
                            seen.insert(entry.incoming.identity, entry.time);
                            pending.insert(entry.seq, entry);
                        }
                        Record::Handed(seq) => {
                            pending.remove(&seq);
                        }
                        Record::Seen(id, time) => {
                            seen.insert(id, time);
                        }
                    }
                    at += used;
                }
                None => {
                    // Damage: go on from the next sync word.
                    let next = bytes[at + 1..]
                        .windows(SYNC.len())
                        .position(|w| w == SYNC)
                        .map_or(bytes.len(), |p| at + 1 + p);
                    discarded_bytes += next - at;
                    needs_rewrite = true;
                    at = next;
                }
            }
        }
        seen.retain(|_, t| t.saturating_add(window_micros) > now);
        let file = private_file_options()
            .create(true)
            .append(true)
            .open(path)?;
        let mut inbox = Inbox {
            path: path.to_path_buf(),
            len: bytes.len() as u64,
            file,
            window: window_micros,
            seen,
            pending,
            next_seq,
            records,
        };
        if needs_rewrite || inbox.records > inbox.live() {
            inbox.rewrite()?;
        }
        let replay = Replay {
            remembered: inbox.seen.len(),
            pending: inbox.pending.len(),
            discarded_bytes,
        };
        Ok((inbox, replay))
    }

    /// Where the inbox lives.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether a message of identity `id` was recorded within the window
    /// before `now`: a repeat, to suppress (and acknowledge).
    pub fn is_duplicate(&self, id: &Identity, now: u64) -> bool {
        self.seen
            .get(id)
            .is_some_and(|t| t.saturating_add(self.window) > now)
    }

    /// Appends a received message (not synced: call [`sync`](Self::sync)
    /// before handing it over or acknowledging it) and remembers its
    /// identity; returns its number. A failed write is cut back out of the
    /// file.
    pub fn record(&mut self, incoming: Incoming, now: u64) -> io::Result<u64> {
        let entry = InboxEntry {
            seq: self.next_seq,
            time: now,
            incoming,
        };
        self.append(&framed(&received_payload(&entry)))?;
        self.next_seq += 1;
        self.seen.insert(entry.incoming.identity, now);
        self.pending.insert(entry.seq, entry);
        Ok(self.next_seq - 1)
    }

    /// Remembers `id`, received at `time` and handed over already (a
    /// *seen* record, appended, not synced), unless it is past the window.
    pub fn remember(&mut self, id: Identity, time: u64, now: u64) -> io::Result<()> {
        if time.saturating_add(self.window) <= now || self.seen.contains_key(&id) {
            return Ok(());
        }
        self.append(&framed(&seen_payload(&id, time)))?;
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
        self.file.sync_data()
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
        self.append(&framed(&payload))?;
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

    fn append(&mut self, record: &[u8]) -> io::Result<()> {
        if let Err(e) = self.file.write_all(record) {
            // Leave no partial record behind (the next start would skip
            // it anyway).
            let _ = self.file.set_len(self.len);
            return Err(e);
        }
        self.len += record.len() as u64;
        self.records += 1;
        Ok(())
    }

    /// Writes the live records to a new file and puts it in place.
    fn rewrite(&mut self) -> io::Result<()> {
        let tmp = self.path.with_extension("tmp");
        let mut bytes = MAGIC.to_vec();
        let pending_ids: std::collections::HashSet<Identity> =
            self.pending.values().map(|e| e.incoming.identity).collect();
        let mut seen: Vec<(&Identity, &u64)> = self
            .seen
            .iter()
            .filter(|(id, _)| !pending_ids.contains(id))
            .collect();
        seen.sort_by_key(|(_, t)| **t);
        let mut records = 0;
        for (id, time) in seen {
            bytes.extend_from_slice(&framed(&seen_payload(id, *time)));
            records += 1;
        }
        for entry in self.pending.values() {
            bytes.extend_from_slice(&framed(&received_payload(entry)));
            records += 1;
        }
        {
            let mut out = private_file_options()
                .write(true)
                .create(true)
                .truncate(true)
                .open(&tmp)?;
            out.write_all(&bytes)?;
            out.sync_all()?;
        }
        std::fs::rename(&tmp, &self.path)?;
        if let Some(dir) = self.path.parent() {
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        self.file = OpenOptions::new().append(true).open(&self.path)?;
        self.len = bytes.len() as u64;
        self.records = records;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
