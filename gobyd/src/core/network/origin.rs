//! The origin's side of routed messages: what this node sent through a
//! relay and still waits to hear the end-to-end ack of.
//!
//! A routed message lives first in the outbox journal (its envelope, until
//! the first relay acknowledges the hop: the relay then has it, journaled);
//! from that ack until the final destination's ack comes back (or the
//! message's lifetime runs out) it lives here, in `DATA_DIR/routes.log`, so
//! that a restart of the origin still tells its client. The file is a
//! record log ([`goby_store::record_log`], magic `GOBYRTE1`); a payload is
//!
//! ```text
//! kind 1, awaiting: entry u64 | dest i32 | number u16 | expires i64 µs | name length u16 | name | message (protobuf)
//! kind 2, done:     entry u64
//! ```
//!
//! (integers little-endian). The awaiting record is synced before the
//! envelope's journal record is given up; a lost done record tells the
//! client once more (an ack or an expiry after a restart).

use std::collections::BTreeMap;
use std::io;
use std::path::Path;

use goby_store::record_log::{Format, RecordLog};

/// The file format of `routes.log`.
pub const ROUTES: Format = Format {
    name: "routes",
    magic: b"GOBYRTE1",
    sync: [0xA7, 0x52, 0x54, 0x45],
    older: &[],
};

const KIND_AWAITING: u8 = 1;
const KIND_DONE: u8 = 2;

/// A routed message this node originated that wants an end-to-end ack.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pending {
    /// Its journal id (the id its client was given).
    pub entry: u64,
    /// Its final destination.
    pub dest: i32,
    /// Its number on the water.
    pub number: u16,
    /// When its lifetime ends, microseconds since the epoch.
    pub expires: i64,
    /// The type of the message it carries.
    pub name: String,
    /// The message it carries (protobuf encoding).
    pub message: Vec<u8>,
    /// The first relay has it (it left the journal; it is on record here).
    pub hop_acked: bool,
}

fn awaiting_payload(p: &Pending) -> Vec<u8> {
    let mut out = Vec::with_capacity(27 + p.name.len() + p.message.len());
    out.push(KIND_AWAITING);
    out.extend_from_slice(&p.entry.to_le_bytes());
    out.extend_from_slice(&p.dest.to_le_bytes());
    out.extend_from_slice(&p.number.to_le_bytes());
    out.extend_from_slice(&p.expires.to_le_bytes());
    out.extend_from_slice(&(p.name.len() as u16).to_le_bytes());
    out.extend_from_slice(p.name.as_bytes());
    out.extend_from_slice(&p.message);
    out
}

enum Record {
    Awaiting(Pending),
    Done(u64),
}

fn parse(payload: &[u8]) -> Option<Record> {
    let (&kind, rest) = payload.split_first()?;
    match kind {
        KIND_AWAITING => {
            let entry = u64::from_le_bytes(rest.get(0..8)?.try_into().ok()?);
            let dest = i32::from_le_bytes(rest.get(8..12)?.try_into().ok()?);
            let number = u16::from_le_bytes(rest.get(12..14)?.try_into().ok()?);
            let expires = i64::from_le_bytes(rest.get(14..22)?.try_into().ok()?);
            let len = u16::from_le_bytes(rest.get(22..24)?.try_into().ok()?) as usize;
            let name = std::str::from_utf8(rest.get(24..24 + len)?)
                .ok()?
                .to_string();
            Some(Record::Awaiting(Pending {
                entry,
                dest,
                number,
                expires,
                name,
                message: rest[24 + len..].to_vec(),
                hop_acked: true,
            }))
        }
        KIND_DONE if rest.len() == 8 => {
            Some(Record::Done(u64::from_le_bytes(rest.try_into().ok()?)))
        }
        _ => None,
    }
}

/// The routed messages waiting for their end-to-end ack.
#[derive(Debug)]
pub struct Origin {
    log: RecordLog,
    pending: BTreeMap<u64, Pending>,
    records: usize,
}

impl Origin {
    /// Opens (or creates) `routes.log` at `path` and replays it.
    pub fn open(path: &Path) -> io::Result<Self> {
        let mut log = RecordLog::create_or_open(path, ROUTES)?;
        let bytes = log.read_all()?;
        let replayed = log.replay(&bytes, parse)?;
        let records = replayed.records.len();
        let mut pending = BTreeMap::new();
        for record in replayed.records {
            match record {
                Record::Awaiting(p) => {
                    pending.insert(p.entry, p);
                }
                Record::Done(entry) => {
                    pending.remove(&entry);
                }
            }
        }
        let mut origin = Origin {
            log,
            pending,
            records,
        };
        // A compaction that fails (a full disk) leaves the file whole, to
        // be compacted later: the daemon still starts.
        if replayed.rewrite_advised || origin.records > 2 * origin.pending.len() + 256 {
            if let Err(e) = origin.rewrite() {
                tracing::warn!("{e}: left as it is, to be compacted later");
            }
        }
        Ok(origin)
    }

    /// Messages waiting, by journal id.
    #[cfg(any(test, feature = "internals"))]
    pub fn pending(&self) -> impl Iterator<Item = &Pending> {
        self.pending.values()
    }

    /// Starts waiting for `p`'s end-to-end ack (a message still in the
    /// journal: nothing is written).
    pub fn track(&mut self, p: Pending) {
        self.pending.entry(p.entry).or_insert(p);
    }

    /// The first relay acknowledged message `entry`: it leaves the journal,
    /// so it goes on record here (synced). `false` when it is not waited
    /// for (acked already, or it wants no ack).
    pub fn hop_acked(&mut self, entry: u64) -> io::Result<bool> {
        let Some(p) = self.pending.get_mut(&entry) else {
            return Ok(false);
        };
        if p.hop_acked {
            return Ok(true);
        }
        p.hop_acked = true;
        let payload = awaiting_payload(p);
        self.append(&payload)?;
        self.log.sync()?;
        Ok(true)
    }

    /// The end-to-end ack of publication `number` came from `dest`: the
    /// message it acknowledges, no longer waited for.
    pub fn acked(&mut self, dest: i32, number: u16) -> io::Result<Option<Pending>> {
        let Some(entry) = self
            .pending
            .values()
            .find(|p| p.dest == dest && p.number == number)
            .map(|p| p.entry)
        else {
            return Ok(None);
        };
        self.done(entry)
    }

    /// A relay dropped publication `number` (the hop limit): the message,
    /// no longer waited for. The relay does not say the final destination:
    /// the number alone names it (numbers repeat only every 65536
    /// publications).
    pub fn dropped(&mut self, number: u16) -> io::Result<Option<Pending>> {
        let Some(entry) = self
            .pending
            .values()
            .find(|p| p.number == number)
            .map(|p| p.entry)
        else {
            return Ok(None);
        };
        self.done(entry)
    }

    /// Message `entry` is no longer waited for (acked, expired, or gone
    /// from the queue before its first hop): returns it.
    pub fn done(&mut self, entry: u64) -> io::Result<Option<Pending>> {
        let Some(p) = self.pending.remove(&entry) else {
            return Ok(None);
        };
        if p.hop_acked {
            let mut payload = vec![KIND_DONE];
            payload.extend_from_slice(&entry.to_le_bytes());
            self.append(&payload)?;
            if self.records > 2 * self.pending.len() + 256 {
                self.rewrite()?;
            }
        }
        Ok(Some(p))
    }

    /// The messages past the first relay whose lifetime ended by `now`
    /// (microseconds since the epoch): no longer waited for.
    pub fn expired(&mut self, now: i64) -> io::Result<Vec<Pending>> {
        let due: Vec<u64> = self
            .pending
            .values()
            .filter(|p| p.hop_acked && p.expires <= now)
            .map(|p| p.entry)
            .collect();
        let mut out = Vec::new();
        for entry in due {
            out.extend(self.done(entry)?);
        }
        Ok(out)
    }

    fn append(&mut self, payload: &[u8]) -> io::Result<()> {
        self.log.append(payload)?;
        self.records += 1;
        Ok(())
    }

    fn rewrite(&mut self) -> io::Result<()> {
        let payloads: Vec<Vec<u8>> = self
            .pending
            .values()
            .filter(|p| p.hop_acked)
            .map(awaiting_payload)
            .collect();
        self.records = payloads.len();
        self.log.rewrite(&payloads)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pending(entry: u64, number: u16) -> Pending {
        Pending {
            entry,
            dest: 3,
            number,
            expires: 1_000,
            name: "goby.example.Command".into(),
            message: vec![8, 3],
            hop_acked: false,
        }
    }

    #[test]
    fn what_passed_the_first_hop_is_waited_for_across_restarts() {
        let dir = std::env::temp_dir().join(format!("gobyd-origin-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("routes.log");
        {
            let mut o = Origin::open(&path).unwrap();
            o.track(pending(10, 10));
            o.track(pending(11, 11));
            o.track(pending(12, 12));
            assert!(o.hop_acked(10).unwrap());
            assert!(o.hop_acked(11).unwrap());
            assert!(!o.hop_acked(99).unwrap());
            assert_eq!(o.acked(3, 11).unwrap().unwrap().entry, 11);
            assert!(o.acked(4, 10).unwrap().is_none());
        }
        // 12 never passed its first hop: the journal has it, not this file.
        let mut o = Origin::open(&path).unwrap();
        let left: Vec<u64> = o.pending().map(|p| p.entry).collect();
        assert_eq!(left, [10]);
        assert!(o.expired(999).unwrap().is_empty());
        assert_eq!(o.expired(1_000).unwrap().len(), 1);
        drop(o);
        assert_eq!(Origin::open(&path).unwrap().pending().count(), 0);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
