//! The receiver's duplicate filter: a message reaches the autonomy side
//! once, however many times it crossed the water.
//!
//! Acoustic links deliver at least once: a sender whose ack was lost (or
//! whose modem reset after the receiver got the packet) sends the message
//! again. The frames stay plain DCCL, so nothing on the wire marks a repeat;
//! the receiver recognises one by its identity
//!
//! ```text
//! (source modem id, DCCL id, first 8 bytes of SHA-256 of the message's DCCL encoding)
//! ```
//!
//! remembered for a window (`duplicate_window_seconds`, by default the
//! longest `ttl` of the queue: a sender stops retrying a message once it
//! expired). The identities live in `DATA_DIR/delivered.log`, each appended
//! and synced to disk *before* the message is handed to clients, so a
//! receiver restarted after a crash still knows what it handed over (a crash
//! between the sync and the hand-over loses that one message to the clients
//! rather than ever giving it twice).
//!
//! The price: a message identical in every field to one handed over within
//! the window, from the same source, is taken for a repeat and suppressed.
//! Messages meant to be sent twice should differ, e.g. by a time or sequence
//! field.
//!
//! File format: records of 28 bytes, `time_micros: u64 LE | src: i32 LE |
//! dccl_id: u32 LE | digest: u64 LE | crc32: u32 LE` (CRC-32/ISO-HDLC of the
//! 24 bytes before it). A torn or corrupt record (power loss) ends the
//! replay; the file is rewritten without it and without expired records.
//! The file holds digests only, no message content (mode 0600, as the other
//! files of the data directory).

use std::collections::HashMap;
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use crc::{Crc, CRC_32_ISO_HDLC};
use sha2::{Digest, Sha256};

use crate::data_dir::private_file_options;

const CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
const RECORD: usize = 28;

/// Who sent a message and what it was: equal identities are the same message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Identity {
    /// Source modem id.
    pub src: i32,
    /// DCCL id of the message type.
    pub dccl_id: u32,
    /// First 8 bytes (little-endian) of SHA-256 of the DCCL encoding.
    pub digest: u64,
}

impl Identity {
    /// The identity of a message from `src` of type `dccl_id` encoded as
    /// `dccl_bytes`.
    pub fn of(src: i32, dccl_id: u32, dccl_bytes: &[u8]) -> Self {
        let hash = Sha256::digest(dccl_bytes);
        let mut first = [0u8; 8];
        first.copy_from_slice(&hash[..8]);
        Identity {
            src,
            dccl_id,
            digest: u64::from_le_bytes(first),
        }
    }
}

/// The messages handed over within the window, on disk.
#[derive(Debug)]
pub struct DeliveredLog {
    path: PathBuf,
    file: File,
    /// Microseconds an identity is remembered.
    window: u64,
    seen: HashMap<Identity, u64>,
    /// Records in the file (live or not).
    records: usize,
}

/// What opening the log found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Replay {
    /// Identities still within the window.
    pub remembered: usize,
    /// Bytes of a torn or corrupt tail, dropped.
    pub discarded_bytes: usize,
}

impl DeliveredLog {
    /// Opens (or creates) the log at `path`, remembering for `window_micros`
    /// from `now` (microseconds since the epoch).
    pub fn open(path: &Path, window_micros: u64, now: u64) -> std::io::Result<(Self, Replay)> {
        let mut bytes = Vec::new();
        match File::open(path) {
            Ok(mut f) => {
                f.read_to_end(&mut bytes)?;
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        let mut seen = HashMap::new();
        let mut at = 0;
        while at + RECORD <= bytes.len() {
            let record = &bytes[at..at + RECORD];
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
            seen.insert(id, time);
            at += RECORD;
        }
        let discarded_bytes = bytes.len() - at;
        seen.retain(|_, t| t.saturating_add(window_micros) > now);
        let mut log = DeliveredLog {
            path: path.to_path_buf(),
            file: private_file_options()
                .create(true)
                .append(true)
                .open(path)?,
            window: window_micros,
            records: at / RECORD,
            seen,
        };
        if discarded_bytes > 0 || log.records > log.seen.len() {
            log.rewrite()?;
        }
        let remembered = log.seen.len();
        Ok((
            log,
            Replay {
                remembered,
                discarded_bytes,
            },
        ))
    }

    /// Where the log lives.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Identities remembered now.
    pub fn len(&self) -> usize {
        self.seen.len()
    }

    /// Whether nothing is remembered.
    pub fn is_empty(&self) -> bool {
        self.seen.is_empty()
    }

    /// Whether `id` was handed over within the window before `now`.
    pub fn is_duplicate(&self, id: &Identity, now: u64) -> bool {
        self.seen
            .get(id)
            .is_some_and(|t| t.saturating_add(self.window) > now)
    }

    /// Checks `id` and, when it is new, records it durably (appended and
    /// synced) before returning `true`: the caller may then hand the
    /// message over. `false`: a repeat within the window, to suppress.
    pub fn first_time(&mut self, id: Identity, now: u64) -> std::io::Result<bool> {
        if self.is_duplicate(&id, now) {
            return Ok(false);
        }
        let mut record = [0u8; RECORD];
        record[0..8].copy_from_slice(&now.to_le_bytes());
        record[8..12].copy_from_slice(&id.src.to_le_bytes());
        record[12..16].copy_from_slice(&id.dccl_id.to_le_bytes());
        record[16..24].copy_from_slice(&id.digest.to_le_bytes());
        let crc = CRC.checksum(&record[..24]);
        record[24..28].copy_from_slice(&crc.to_le_bytes());
        self.file.write_all(&record)?;
        self.file.sync_data()?;
        self.records += 1;
        self.seen.insert(id, now);
        self.forget_expired(now)?;
        Ok(true)
    }

    /// Forgets identities older than the window; rewrites the file when
    /// most of its records are forgotten.
    fn forget_expired(&mut self, now: u64) -> std::io::Result<()> {
        let window = self.window;
        self.seen.retain(|_, t| t.saturating_add(window) > now);
        if self.records > 2 * self.seen.len() + 1024 {
            self.rewrite()?;
        }
        Ok(())
    }

    /// Writes the remembered identities to a new file and puts it in place.
    fn rewrite(&mut self) -> std::io::Result<()> {
        let tmp = self.path.with_extension("tmp");
        {
            let mut out = private_file_options()
                .write(true)
                .create(true)
                .truncate(true)
                .open(&tmp)?;
            let mut entries: Vec<(&Identity, &u64)> = self.seen.iter().collect();
            entries.sort_by_key(|(_, t)| **t);
            let mut bytes = Vec::with_capacity(entries.len() * RECORD);
            for (id, time) in entries {
                let start = bytes.len();
                bytes.extend_from_slice(&time.to_le_bytes());
                bytes.extend_from_slice(&id.src.to_le_bytes());
                bytes.extend_from_slice(&id.dccl_id.to_le_bytes());
                bytes.extend_from_slice(&id.digest.to_le_bytes());
                let crc = CRC.checksum(&bytes[start..]);
                bytes.extend_from_slice(&crc.to_le_bytes());
            }
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
        self.records = self.seen.len();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("gobyd-dedup-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_repeat_is_suppressed_within_the_window_and_across_a_restart() {
        let d = dir("restart");
        let path = d.join("delivered.log");
        let a = Identity::of(2, 4, b"\x01\x02");
        let b = Identity::of(2, 4, b"\x01\x03");
        let other_source = Identity::of(3, 4, b"\x01\x02");
        let (mut log, replay) = DeliveredLog::open(&path, 10_000_000, 1_000).unwrap();
        assert_eq!(replay, Replay::default());
        assert!(log.first_time(a, 1_000).unwrap());
        assert!(!log.first_time(a, 2_000).unwrap());
        assert!(log.first_time(b, 2_000).unwrap());
        assert!(log.first_time(other_source, 2_000).unwrap());
        drop(log);

        // Restarted: still known; a torn record at the end is dropped.
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        f.write_all(&[1, 2, 3]).unwrap();
        drop(f);
        let (mut log, replay) = DeliveredLog::open(&path, 10_000_000, 3_000).unwrap();
        assert_eq!(replay.remembered, 3);
        assert_eq!(replay.discarded_bytes, 3);
        assert!(!log.first_time(a, 3_000).unwrap());

        // Past the window it is new again.
        assert!(log.first_time(a, 1_000 + 10_000_000).unwrap());
        let _ = std::fs::remove_dir_all(&d);
    }
}
