//! Record logs: the one file format under the outbox journal (the queue's
//! `journal`), the receiver's inbox and the network layer's logs (`gobyd`),
//! and the code that reads, appends to and rewrites such files. Each owner
//! defines its [`Format`] and what its payloads hold, next to itself; this
//! module owns everything around them.
//!
//! # Format
//!
//! ```text
//! file   = magic (8 bytes) | record*
//! record = sync (4 bytes) | length: u32 LE (of the payload) | crc32: u32 LE (of length and payload) | payload
//! ```
//!
//! Each kind of file has its magic and its sync word ([`Format`]): the
//! outbox journal `GOBYJNLD` (reading `GOBYJNL2`), the inbox `GOBYINB1`,
//! the routes `GOBYRTE1` and the transfers `GOBYXFR1`; each sync word starts
//! with `A7`.
//!
//! The CRC-32 is ISO-HDLC (the zlib and Ethernet one, [`CRC32`]). A payload
//! holds at most [`MAX_PAYLOAD`] bytes (16 MiB); a length above it marks
//! damage. The limit is the journal's: it has accepted (and reported
//! accepted) messages up to that size, and a smaller one would turn those
//! records into "damage" at the next start and lose owed messages. Nothing
//! the inbox writes comes near it (link frames are a few kilobytes at most).
//! What the limit bounds is the work a damaged length costs: replay
//! computes the CRC over at most that many bytes before it rejects the
//! record and resynchronises; replay holds the whole file in memory in
//! either case.
//!
//! # Faults
//!
//! Faults cost the records they touch, never those after them:
//!
//! - a record whose CRC does not match, whose length is over the limit or
//!   runs past the end of the file, or whose payload its owner cannot read,
//!   is skipped: replay looks for the next sync word and goes on from the
//!   first record there that checks out (a single flipped bit anywhere loses
//!   at most the record holding it);
//! - bytes after the last good record (a write torn by a crash) are cut off;
//!   the file is never cut behind a good record. Skipped and cut bytes are
//!   counted in [`Replayed::discarded_bytes`]; damage left between good
//!   records sets [`Replayed::rewrite_advised`] (each owner decides whether
//!   to rewrite);
//! - a header that is one of the format's older magics (the same framing,
//!   payloads its owner still reads, and a kind of payload an earlier
//!   version could not read: [`Format::older`]) is good: it is rewritten
//!   with the current magic before anything is appended, so that the
//!   earlier version refuses the file rather than drops what it cannot read;
//! - a header within two bits of the magic, on a file that holds nothing
//!   after it or at least one good record, is damage: it is rewritten in
//!   place and its 8 bytes counted as discarded. Any other header is not
//!   ours ([`LogError::NotOurs`]) and the file is left untouched. A file
//!   shorter than the magic and a prefix of it (new, or its header torn) is
//!   started anew;
//! - an append that fails (full disk, I/O error) is undone: the file is cut
//!   back to its last whole record. While the undo itself fails, every
//!   append is refused (nothing is appended behind a partial record); once
//!   the cut succeeds, appending resumes. Should the process die first, the
//!   partial record is skipped at the next start;
//! - a rewrite (compaction) writes a hidden file beside the file
//!   (`.NAME.part`), syncs it, renames it over the file and syncs the
//!   directory ([`crate::file::write_atomically`]); any failure, the
//!   directory sync included, is reported.
//!
//! Files are created with mode 0600 (on Unix): they hold the mission's
//! messages ([`crate::file`]).

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use crc::{Crc, CRC_32_ISO_HDLC};

use crate::file::{private_file_options, replace, sync_parent};

/// The CRC of every record (ISO-HDLC).
pub const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
/// Bytes of record framing (sync word, length and CRC).
pub const FRAMING: usize = 12;
/// Largest payload a record may have; a length above it marks damage (see
/// the [module documentation](self) for why 16 MiB).
pub const MAX_PAYLOAD: usize = 16 * 1024 * 1024;
/// Capacity of the append buffer a log keeps between records (a larger
/// one, for a large record, is let go).
const KEPT_SCRATCH: usize = 64 * 1024;

/// The parameters of one kind of record log file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Format {
    /// What the file is, for messages ("journal", "inbox").
    pub name: &'static str,
    /// First bytes of the file.
    pub magic: &'static [u8; 8],
    /// First bytes of every record.
    pub sync: [u8; 4],
    /// Magics of earlier versions of the format: their files are read as
    /// they are and take the current magic. Each is more than two bits
    /// from the current one, so that a version that knows only it does
    /// not take the current magic for a damaged header of its own.
    pub older: &'static [&'static [u8; 8]],
}

impl Format {
    /// The record holding `payload`: sync word, length, CRC, payload.
    pub fn frame(&self, payload: &[u8]) -> Vec<u8> {
        let mut out = Vec::with_capacity(FRAMING + payload.len());
        self.frame_into(&mut out, payload);
        out
    }

    /// Appends the record holding `payload` to `out`.
    pub fn frame_into(&self, out: &mut Vec<u8>, payload: &[u8]) {
        let len = (payload.len() as u32).to_le_bytes();
        let mut digest = CRC32.digest();
        digest.update(&len);
        digest.update(payload);
        out.extend_from_slice(&self.sync);
        out.extend_from_slice(&len);
        out.extend_from_slice(&digest.finalize().to_le_bytes());
        out.extend_from_slice(payload);
    }

    /// The payload of the record at `at` and the offset after the record;
    /// `None` where no whole, sound record starts.
    pub fn record_at<'a>(&self, bytes: &'a [u8], at: usize) -> Option<(&'a [u8], usize)> {
        if bytes.get(at..at.checked_add(self.sync.len())?)? != self.sync {
            return None;
        }
        unsynced_record_at(bytes, at + self.sync.len())
    }

    /// Offset of the first sync word at or after `from`.
    fn find_sync(&self, bytes: &[u8], from: usize) -> Option<usize> {
        bytes
            .get(from..)?
            .windows(self.sync.len())
            .position(|w| w == self.sync)
            .map(|p| from + p)
    }

    /// Replays `bytes` without touching any file; `None` when they are not
    /// a file of this format.
    fn scan<T>(&self, bytes: &[u8], mut parse: impl FnMut(&[u8]) -> Option<T>) -> Option<Scan<T>> {
        let magic = self.magic;
        if bytes.len() < magic.len() {
            // New, or torn while writing the header: nothing was recorded.
            return magic.starts_with(bytes).then(|| Scan {
                replayed: Replayed {
                    records: Vec::new(),
                    discarded_bytes: bytes.len() as u64,
                    rewrite_advised: false,
                },
                header: Header::New,
                end: magic.len(),
                offsets: Vec::new(),
                damage: (!bytes.is_empty())
                    .then_some(Damage {
                        offset: 0,
                        len: bytes.len() as u64,
                        tail: true,
                    })
                    .into_iter()
                    .collect(),
            });
        }
        let header = if bytes.starts_with(magic) {
            Header::Good
        } else if self.older.iter().any(|m| bytes.starts_with(*m)) {
            Header::Older
        } else if magic
            .iter()
            .zip(bytes)
            .map(|(a, b)| (a ^ b).count_ones())
            .sum::<u32>()
            <= 2
        {
            Header::Damaged
        } else {
            return None;
        };
        let mut records = Vec::new();
        let mut offsets = Vec::new();
        let mut damage = Vec::new();
        let mut discarded_bytes = 0;
        let mut rewrite_advised = false;
        let mut at = magic.len();
        let mut end = at;
        // Bytes skipped since the last good record: discarded once a good
        // record follows them, else part of the tail.
        let mut skipped = 0;
        while at < bytes.len() {
            let record = self
                .record_at(bytes, at)
                .and_then(|(payload, next)| Some((parse(payload)?, next)));
            match record {
                Some((record, next)) => {
                    records.push(record);
                    offsets.push(at as u64);
                    if skipped > 0 {
                        damage.push(Damage {
                            offset: at as u64 - skipped,
                            len: skipped,
                            tail: false,
                        });
                        discarded_bytes += skipped;
                        skipped = 0;
                        rewrite_advised = true;
                    }
                    at = next;
                    end = next;
                }
                None => match self.find_sync(bytes, at + 1) {
                    Some(next) => {
                        skipped += (next - at) as u64;
                        at = next;
                    }
                    None => break,
                },
            }
        }
        if header == Header::Damaged {
            // Ours only if it holds nothing or at least one good record.
            if records.is_empty() && bytes.len() > magic.len() {
                return None;
            }
            discarded_bytes += magic.len() as u64;
            damage.insert(
                0,
                Damage {
                    offset: 0,
                    len: magic.len() as u64,
                    tail: false,
                },
            );
        }
        // A torn or damaged tail, with no good record after it.
        discarded_bytes += (bytes.len() - end) as u64;
        if end < bytes.len() {
            damage.push(Damage {
                offset: end as u64,
                len: (bytes.len() - end) as u64,
                tail: true,
            });
        }
        Some(Scan {
            replayed: Replayed {
                records,
                discarded_bytes,
                rewrite_advised,
            },
            header,
            end,
            offsets,
            damage,
        })
    }

    /// Reads `bytes`, the content of a file of this format, as replay
    /// would, without touching any file: each good record (its payload as
    /// `parse` reads it) with its offset in the file, and each span replay
    /// skips or cuts off. `None` when the bytes are not a file of this
    /// format. For tools that read a data directory after a mission.
    pub fn inspect<T>(
        &self,
        bytes: &[u8],
        parse: impl FnMut(&[u8]) -> Option<T>,
    ) -> Option<Inspected<T>> {
        let scan = self.scan(bytes, parse)?;
        Some(Inspected {
            records: scan
                .offsets
                .into_iter()
                .zip(scan.replayed.records)
                .collect(),
            damage: scan.damage,
        })
    }
}

/// The payload of a record without a sync word (length, CRC, payload) at
/// `at`, and the offset after it; `None` where no whole, sound record
/// starts. The framing of [`Format::record_at`] after its sync word, and
/// the whole framing of the journal's first format.
pub fn unsynced_record_at(bytes: &[u8], at: usize) -> Option<(&[u8], usize)> {
    let len_bytes: [u8; 4] = bytes.get(at..at.checked_add(4)?)?.try_into().ok()?;
    let len = u32::from_le_bytes(len_bytes) as usize;
    if len > MAX_PAYLOAD {
        return None;
    }
    let crc = u32::from_le_bytes(bytes.get(at + 4..at + 8)?.try_into().ok()?);
    let start = at + 8;
    let payload = bytes.get(start..start.checked_add(len)?)?;
    let mut digest = CRC32.digest();
    digest.update(&len_bytes);
    digest.update(payload);
    (digest.finalize() == crc).then_some((payload, start + len))
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Header {
    /// Shorter than the magic and a prefix of it: to be written.
    New,
    Good,
    /// Within two bits of the magic: to be put right.
    Damaged,
    /// An older magic of the format: good, to take the current one.
    Older,
}

/// What a replay found, before any repair.
struct Scan<T> {
    replayed: Replayed<T>,
    header: Header,
    /// End of the last good record (of the header when there is none).
    end: usize,
    /// Offset of each good record, in the order of `replayed.records`.
    offsets: Vec<u64>,
    /// Spans skipped or cut off, in file order.
    damage: Vec<Damage>,
}

/// A span of a record log that replay skips (damaged records, a damaged
/// header) or cuts off (a torn tail, with no good record after it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Damage {
    /// Offset of its first byte in the file.
    pub offset: u64,
    /// Its length in bytes.
    pub len: u64,
    /// It runs to the end of the file: a write torn by a crash, most
    /// often (a kill or power loss while appending).
    pub tail: bool,
}

/// What [`Format::inspect`] found in a file, without repairing anything.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inspected<T> {
    /// The good records, each with the offset of its sync word, in file
    /// order.
    pub records: Vec<(u64, T)>,
    /// The spans replay skips or cuts off, in file order.
    pub damage: Vec<Damage>,
}

/// What replaying a record log found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Replayed<T> {
    /// The good records, as the owner's parser read their payloads, in
    /// file order.
    pub records: Vec<T>,
    /// Bytes skipped or cut off: damaged records, a torn tail, a damaged
    /// header (0 for a clean file).
    pub discarded_bytes: u64,
    /// Damage is left between good records (replay skips it again at every
    /// start): rewriting the live records is advisable.
    pub rewrite_advised: bool,
}

/// Errors of a record log.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// The file could not be read or written.
    #[error(transparent)]
    Io(#[from] io::Error),
    /// The file is not of this format (its header is not the magic, nor a
    /// damaged one); it was left untouched.
    #[error("not a goby {0} (unknown header)")]
    NotOurs(&'static str),
    /// A payload over [`MAX_PAYLOAD`]; nothing was written.
    #[error("record of {0} bytes is over the limit of {MAX_PAYLOAD} bytes")]
    TooLarge(usize),
}

impl From<LogError> for io::Error {
    fn from(e: LogError) -> Self {
        match e {
            LogError::Io(e) => e,
            LogError::NotOurs(_) => io::Error::new(io::ErrorKind::InvalidData, e.to_string()),
            LogError::TooLarge(_) => io::Error::new(io::ErrorKind::InvalidInput, e.to_string()),
        }
    }
}

/// The file under a record log: the few operations it needs, so that faults
/// (a full disk, failing writes) can be injected in tests. Implemented for
/// [`File`] and [`MemoryFile`].
pub trait LogFile: Send + std::fmt::Debug {
    /// The whole content.
    fn read_all(&mut self) -> io::Result<Vec<u8>>;
    /// Writes `bytes` at `offset`; on error, a prefix may have been written.
    fn write_at(&mut self, offset: u64, bytes: &[u8]) -> io::Result<()>;
    /// Cuts or extends the file to `len` bytes.
    fn set_len(&mut self, len: u64) -> io::Result<()>;
    /// Waits until the content is on disk.
    fn sync(&mut self) -> io::Result<()>;
    /// A second handle on the same file whose `sync_data` makes everything
    /// written before the call durable.
    fn sync_handle(&self) -> io::Result<File>;
    /// Points at the file now at `path` (after a rewrite was renamed over
    /// it).
    fn reopen(&mut self, path: &Path) -> io::Result<()>;
    /// Puts a file holding `bytes` at `path`, whole or not at all
    /// ([`crate::file::replace`]: written beside it, synced, renamed over
    /// it). The handle still points at the old file until
    /// [`reopen`](Self::reopen).
    fn replace(&mut self, path: &Path, bytes: &[u8]) -> io::Result<()> {
        replace(path, bytes)
    }
    /// Syncs the directory holding `path`, so that a file created or
    /// renamed there survives power loss.
    fn sync_dir(&self, path: &Path) -> io::Result<()> {
        sync_parent(path)
    }
}

impl LogFile for File {
    fn read_all(&mut self) -> io::Result<Vec<u8>> {
        let mut bytes = Vec::new();
        self.seek(SeekFrom::Start(0))?;
        self.read_to_end(&mut bytes)?;
        Ok(bytes)
    }

    fn write_at(&mut self, offset: u64, bytes: &[u8]) -> io::Result<()> {
        // One system call (pwrite) where there is one.
        #[cfg(unix)]
        {
            std::os::unix::fs::FileExt::write_all_at(self, bytes, offset)
        }
        #[cfg(not(unix))]
        {
            self.seek(SeekFrom::Start(offset))?;
            self.write_all(bytes)
        }
    }

    fn set_len(&mut self, len: u64) -> io::Result<()> {
        File::set_len(self, len)
    }

    fn sync(&mut self) -> io::Result<()> {
        self.sync_data()
    }

    fn sync_handle(&self) -> io::Result<File> {
        self.try_clone()
    }

    fn reopen(&mut self, path: &Path) -> io::Result<()> {
        *self = OpenOptions::new().read(true).write(true).open(path)?;
        Ok(())
    }
}

/// A record log file in memory, for replaying bytes without a disk
/// (fuzzing, inspection, tests). Clones share the content.
#[derive(Debug, Clone, Default)]
pub struct MemoryFile(Arc<Mutex<Vec<u8>>>);

impl MemoryFile {
    /// A file holding `bytes`.
    pub fn new(bytes: Vec<u8>) -> Self {
        Self(Arc::new(Mutex::new(bytes)))
    }

    /// The content now.
    pub fn contents(&self) -> Vec<u8> {
        self.bytes().clone()
    }

    fn bytes(&self) -> std::sync::MutexGuard<'_, Vec<u8>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl LogFile for MemoryFile {
    fn read_all(&mut self) -> io::Result<Vec<u8>> {
        Ok(self.contents())
    }
    fn write_at(&mut self, offset: u64, bytes: &[u8]) -> io::Result<()> {
        let offset = usize::try_from(offset).map_err(io::Error::other)?;
        let end = offset + bytes.len();
        let mut content = self.bytes();
        if content.len() < end {
            content.resize(end, 0);
        }
        content[offset..end].copy_from_slice(bytes);
        Ok(())
    }
    fn set_len(&mut self, len: u64) -> io::Result<()> {
        self.bytes()
            .resize(usize::try_from(len).map_err(io::Error::other)?, 0);
        Ok(())
    }
    fn sync(&mut self) -> io::Result<()> {
        Ok(())
    }
    fn sync_handle(&self) -> io::Result<File> {
        Err(io::Error::other("a record log in memory has no file"))
    }
    fn reopen(&mut self, _: &Path) -> io::Result<()> {
        Ok(())
    }
    fn replace(&mut self, _: &Path, bytes: &[u8]) -> io::Result<()> {
        *self.bytes() = bytes.to_vec();
        Ok(())
    }
    fn sync_dir(&self, _: &Path) -> io::Result<()> {
        Ok(())
    }
}

/// An open record log: a file of one [`Format`], appended to after its last
/// whole record.
#[derive(Debug)]
pub struct RecordLog {
    format: Format,
    path: PathBuf,
    file: Box<dyn LogFile>,
    /// Length of the file up to the end of its last whole record.
    len: u64,
    /// A failed write may have left bytes after `len`: cut them before the
    /// next append.
    dirty: bool,
    /// A rewrite was renamed over the file but the handle could not be
    /// pointed at it: reopen before the next append.
    stale: bool,
    /// The record being appended, kept between appends (no allocation per
    /// record once it is large enough).
    scratch: Vec<u8>,
    /// The generation of the file's contents, for [`crate::power`]: new at
    /// each replay and rewrite.
    generation: u64,
}

/// A second handle on a record log's file, taken by
/// [`RecordLog::sync_handle`]: its [`sync_data`](Self::sync_data) makes
/// everything appended before it was taken durable, from any thread.
#[derive(Debug)]
pub struct SyncHandle {
    file: File,
    path: PathBuf,
    generation: u64,
    len: u64,
}

impl SyncHandle {
    /// Waits until everything appended before the handle was taken is on
    /// disk (`fdatasync`). Errors: the operating system's.
    pub fn sync_data(&self) -> io::Result<()> {
        self.file.sync_data()?;
        crate::power::durable(&self.path, self.generation, self.len);
        Ok(())
    }
}

impl RecordLog {
    /// Opens (or creates, mode 0600) the file at `path` and replays it,
    /// reading each good record's payload with `parse` (a payload it
    /// refuses counts as damage).
    pub fn open<T>(
        path: impl AsRef<Path>,
        format: Format,
        parse: impl FnMut(&[u8]) -> Option<T>,
    ) -> Result<(Self, Replayed<T>), LogError> {
        let mut log = Self::create_or_open(path, format)?;
        let bytes = log.read_all()?;
        let replayed = log.replay(&bytes, parse)?;
        Ok((log, replayed))
    }

    /// Opens (or creates, mode 0600) the file at `path`, without reading
    /// it: [`read_all`](Self::read_all) then [`replay`](Self::replay) (or
    /// [`rewrite`](Self::rewrite), for a file of an older format).
    pub fn create_or_open(path: impl AsRef<Path>, format: Format) -> io::Result<Self> {
        let path = path.as_ref();
        let file = private_file_options()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)?;
        Ok(Self::with_file(path, format, file))
    }

    /// The log held by `file`, named `path` (where rewrites go), not read
    /// yet.
    pub fn with_file(path: impl AsRef<Path>, format: Format, file: impl LogFile + 'static) -> Self {
        Self {
            format,
            path: path.as_ref().to_path_buf(),
            file: Box::new(file),
            len: 0,
            dirty: false,
            stale: false,
            scratch: Vec::new(),
            generation: 0,
        }
    }

    /// The whole content of the file.
    pub fn read_all(&mut self) -> io::Result<Vec<u8>> {
        self.file.read_all()
    }

    /// Replays `bytes`, the content of the file, and repairs what can be
    /// repaired in place: a new file gets its header, a damaged header is
    /// put right, a torn tail is cut off. Damage between good records is
    /// left (see [`Replayed::rewrite_advised`]). Appends go after the last
    /// good record.
    pub fn replay<T>(
        &mut self,
        bytes: &[u8],
        parse: impl FnMut(&[u8]) -> Option<T>,
    ) -> Result<Replayed<T>, LogError> {
        let scan = self
            .format
            .scan(bytes, parse)
            .ok_or(LogError::NotOurs(self.format.name))?;
        if scan.header != Header::Good {
            crate::space::check(&self.path)?;
        }
        match scan.header {
            Header::New => {
                self.file.set_len(0)?;
                self.file.write_at(0, self.format.magic)?;
                self.file.sync()?;
                self.file.sync_dir(&self.path)?;
            }
            Header::Damaged | Header::Older => self.file.write_at(0, self.format.magic)?,
            Header::Good => {}
        }
        let cut = scan.header != Header::New && scan.end < bytes.len();
        if cut {
            self.file.set_len(scan.end as u64)?;
        }
        if cut || matches!(scan.header, Header::Damaged | Header::Older) {
            self.file.sync()?;
        }
        self.len = scan.end as u64;
        self.dirty = false;
        // What it holds now is on the disk: synced by the repairs above, or
        // found there.
        self.generation = crate::power::generation();
        crate::power::durable(&self.path, self.generation, self.len);
        Ok(scan.replayed)
    }

    /// Appends the record holding `payload` after the last whole record
    /// (not synced); returns the bytes it takes in the file. A failed write
    /// is undone (the file cut back); while that fails too, every append is
    /// refused.
    pub fn append(&mut self, payload: &[u8]) -> Result<u64, LogError> {
        self.append_with(|out| out.extend_from_slice(payload))
    }

    /// Appends the record whose payload `fill` writes (to the end of the
    /// buffer it is given), as [`append`](Self::append) does: the record is
    /// framed in a buffer the log keeps, without a copy of the payload of
    /// its own.
    pub fn append_with(&mut self, fill: impl FnOnce(&mut Vec<u8>)) -> Result<u64, LogError> {
        let mut record = std::mem::take(&mut self.scratch);
        record.clear();
        record.resize(FRAMING, 0);
        fill(&mut record);
        let written = self.append_framed(&mut record);
        if record.capacity() <= KEPT_SCRATCH {
            self.scratch = record;
        }
        written
    }

    /// Frames and appends the record whose payload follows [`FRAMING`]
    /// bytes of room in `record`.
    fn append_framed(&mut self, record: &mut [u8]) -> Result<u64, LogError> {
        let payload_len = record.len() - FRAMING;
        if payload_len > MAX_PAYLOAD {
            return Err(LogError::TooLarge(payload_len));
        }
        let len = (payload_len as u32).to_le_bytes();
        let mut digest = CRC32.digest();
        digest.update(&len);
        digest.update(&record[FRAMING..]);
        record[..4].copy_from_slice(&self.format.sync);
        record[4..8].copy_from_slice(&len);
        record[8..FRAMING].copy_from_slice(&digest.finalize().to_le_bytes());
        if self.stale {
            self.file.reopen(&self.path)?;
            self.stale = false;
        }
        if self.dirty {
            self.file.set_len(self.len)?;
            self.dirty = false;
        }
        crate::space::check(&self.path)?;
        if let Err(e) = self.file.write_at(self.len, record) {
            self.dirty = self.file.set_len(self.len).is_err();
            return Err(e.into());
        }
        self.len += record.len() as u64;
        Ok(record.len() as u64)
    }

    /// Waits until everything appended so far is on disk.
    pub fn sync(&mut self) -> io::Result<()> {
        self.file.sync()?;
        crate::power::durable(&self.path, self.generation, self.len);
        Ok(())
    }

    /// A second handle on the file whose `sync_data` makes everything
    /// appended before the call durable (for syncing on another thread).
    pub fn sync_handle(&self) -> io::Result<SyncHandle> {
        Ok(SyncHandle {
            file: self.file.sync_handle()?,
            path: self.path.clone(),
            generation: self.generation,
            len: self.len,
        })
    }

    /// Replaces the file with one holding the records of `payloads` only,
    /// by rename (see the [module documentation](self)). On an error before
    /// the rename the old file stays as it was; after it (the directory
    /// sync failing) the new file is in place, and the error is reported
    /// all the same.
    pub fn rewrite<P: AsRef<[u8]>>(
        &mut self,
        payloads: impl IntoIterator<Item = P>,
    ) -> Result<(), LogError> {
        let mut bytes = self.format.magic.to_vec();
        for payload in payloads {
            let payload = payload.as_ref();
            if payload.len() > MAX_PAYLOAD {
                return Err(LogError::TooLarge(payload.len()));
            }
            self.format.frame_into(&mut bytes, payload);
        }
        self.file.replace(&self.path, &bytes)?;
        self.len = bytes.len() as u64;
        self.dirty = false;
        if let Err(e) = self.file.reopen(&self.path) {
            self.stale = true;
            return Err(e.into());
        }
        self.stale = false;
        self.file.sync_dir(&self.path)?;
        self.generation = crate::power::generation();
        crate::power::durable(&self.path, self.generation, self.len);
        Ok(())
    }

    /// Where the file lives (where rewrites go).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its format.
    pub fn format(&self) -> Format {
        self.format
    }

    /// Length of the file up to the end of its last whole record.
    pub fn file_len(&self) -> u64 {
        self.len
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two formats as the journal and the inbox have them.
    const JOURNAL: Format = Format {
        name: "journal",
        magic: b"GOBYJNLD",
        sync: [0xA7, 0x47, 0x4A, 0x52],
        older: &[b"GOBYJNL2"],
    };
    const INBOX: Format = Format {
        name: "inbox",
        magic: b"GOBYINB1",
        sync: [0xA7, 0x49, 0x4E, 0x42],
        older: &[],
    };
    use proptest::prelude::*;

    fn own(payload: &[u8]) -> Option<Vec<u8>> {
        Some(payload.to_vec())
    }

    fn written(format: Format, payloads: &[Vec<u8>]) -> Vec<u8> {
        let mut bytes = format.magic.to_vec();
        for p in payloads {
            format.frame_into(&mut bytes, p);
        }
        bytes
    }

    /// A log opened on a file in memory, and what its replay found.
    type Opened = Result<(RecordLog, Replayed<Vec<u8>>), LogError>;

    fn replay_memory(format: Format, bytes: Vec<u8>) -> (MemoryFile, Opened) {
        let file = MemoryFile::new(bytes);
        let opened = {
            let mut log = RecordLog::with_file("(memory)", format, file.clone());
            log.read_all()
                .map_err(LogError::from)
                .and_then(|bytes| log.replay(&bytes, own))
                .map(|replayed| (log, replayed))
        };
        (file, opened)
    }

    /// Whether `sub` is `all` with some elements left out.
    fn is_subsequence(sub: &[Vec<u8>], all: &[Vec<u8>]) -> bool {
        let mut rest = all.iter();
        sub.iter().all(|s| rest.any(|a| a == s))
    }

    #[test]
    fn the_two_formats_frame_records_as_they_always_did() {
        // A removed record of the journal (id 5) and a handed record of the
        // inbox (seq 5), as the journal and the inbox wrote them before
        // they shared this module.
        let payload = [2, 5, 0, 0, 0, 0, 0, 0, 0];
        let mut digest = CRC32.digest();
        digest.update(&9u32.to_le_bytes());
        digest.update(&payload);
        let crc = digest.finalize().to_le_bytes();
        for (format, sync) in [
            (JOURNAL, [0xA7, 0x47, 0x4A, 0x52]),
            (INBOX, [0xA7, 0x49, 0x4E, 0x42]),
        ] {
            let mut expected = sync.to_vec();
            expected.extend_from_slice(&[9, 0, 0, 0]);
            expected.extend_from_slice(&crc);
            expected.extend_from_slice(&payload);
            assert_eq!(format.frame(&payload), expected, "{}", format.name);
        }
    }

    #[test]
    fn inspect_names_each_record_and_each_damaged_span_by_offset_and_touches_nothing() {
        let records = [b"one".to_vec(), b"two".to_vec(), b"three".to_vec()];
        let mut bytes = written(JOURNAL, &records);
        let second = 8 + FRAMING + 3;
        let third = second + FRAMING + 3;
        // A flipped bit in the second record's payload, and a torn tail.
        bytes[second + FRAMING] ^= 1;
        bytes.extend_from_slice(&JOURNAL.frame(b"torn")[..7]);
        let before = bytes.clone();
        let inspected = JOURNAL.inspect(&bytes, |p| Some(p.to_vec())).unwrap();
        assert_eq!(bytes, before);
        assert_eq!(
            inspected.records,
            [(8, b"one".to_vec()), (third as u64, b"three".to_vec())]
        );
        let end = (third + FRAMING + 5) as u64;
        assert_eq!(
            inspected.damage,
            [
                Damage {
                    offset: second as u64,
                    len: (FRAMING + 3) as u64,
                    tail: false
                },
                Damage {
                    offset: end,
                    len: 7,
                    tail: true
                }
            ]
        );
        assert!(JOURNAL
            .inspect(b"not a journal at all", |_| Some(()))
            .is_none());
        let torn_header = JOURNAL.inspect(&JOURNAL.magic[..5], |_| Some(())).unwrap();
        assert_eq!(torn_header.damage[0].len, 5);
    }

    #[test]
    fn a_file_of_an_older_magic_is_read_and_takes_the_current_one() {
        const OLD: Format = Format {
            magic: b"GOBYJNL2",
            older: &[],
            ..JOURNAL
        };
        let bytes = written(OLD, &[b"one".to_vec(), b"two".to_vec()]);
        let (file, opened) = replay_memory(JOURNAL, bytes.clone());
        let (_, replayed) = opened.unwrap();
        assert_eq!(replayed.records, [b"one".to_vec(), b"two".to_vec()]);
        assert_eq!(replayed.discarded_bytes, 0);
        assert!(file.contents().starts_with(JOURNAL.magic));
        assert_eq!(file.contents()[8..], bytes[8..]);
        // A version that knows only the older magic does not take the
        // current one for a damaged header of its own: it leaves the file.
        let (_, opened) = replay_memory(OLD, file.contents());
        assert!(matches!(opened, Err(LogError::NotOurs(_))));
        for older in JOURNAL.older {
            let bits: u32 = JOURNAL
                .magic
                .iter()
                .zip(*older)
                .map(|(a, b)| (a ^ b).count_ones())
                .sum();
            assert!(bits > 2, "{bits} bits");
        }
    }

    #[test]
    fn a_record_of_one_format_is_not_one_of_the_other() {
        let bytes = written(JOURNAL, &[b"one".to_vec()]);
        let mut inbox = INBOX.magic.to_vec();
        inbox.extend_from_slice(&bytes[8..]);
        let (_, opened) = replay_memory(INBOX, inbox);
        let (_, replayed) = opened.unwrap();
        assert!(replayed.records.is_empty());
        assert_eq!(replayed.discarded_bytes, 15);
    }

    #[test]
    fn a_payload_over_the_limit_is_refused_and_nothing_written() {
        let (file, opened) = replay_memory(INBOX, Vec::new());
        let (mut log, _) = opened.unwrap();
        let err = log.append(&vec![0; MAX_PAYLOAD + 1]).unwrap_err();
        assert!(
            matches!(err, LogError::TooLarge(n) if n == MAX_PAYLOAD + 1),
            "{err}"
        );
        assert_eq!(file.contents(), INBOX.magic);
        let err = log.rewrite([vec![0; MAX_PAYLOAD + 1]]).unwrap_err();
        assert!(matches!(err, LogError::TooLarge(_)), "{err}");
        assert_eq!(file.contents(), INBOX.magic);
        // At the limit, it is a record like any other.
        assert_eq!(
            log.append(&vec![7; MAX_PAYLOAD]).unwrap(),
            (FRAMING + MAX_PAYLOAD) as u64
        );
        let (_, opened) = replay_memory(INBOX, file.contents());
        assert_eq!(opened.unwrap().1.records, [vec![7; MAX_PAYLOAD]]);
    }

    #[test]
    fn damage_between_good_records_advises_a_rewrite_and_a_tail_does_not() {
        let payloads = [b"one".to_vec(), b"two".to_vec(), b"three".to_vec()];
        let mut bytes = written(INBOX, &payloads);
        bytes.extend_from_slice(&INBOX.sync);
        let (file, opened) = replay_memory(INBOX, bytes.clone());
        let replayed = opened.unwrap().1;
        assert!(!replayed.rewrite_advised);
        assert_eq!(replayed.discarded_bytes, 4);
        assert_eq!(file.contents(), written(INBOX, &payloads));

        bytes[8 + FRAMING + 1] ^= 1; // the first record's payload
        let (file, opened) = replay_memory(INBOX, bytes);
        let (mut log, replayed) = opened.unwrap();
        assert!(replayed.rewrite_advised);
        assert_eq!(replayed.records, payloads[1..]);
        assert_eq!(replayed.discarded_bytes, (FRAMING + 3 + 4) as u64);
        log.rewrite(&replayed.records).unwrap();
        assert_eq!(file.contents(), written(INBOX, &payloads[1..]));
    }

    #[test]
    fn a_damaged_header_is_put_right_and_a_foreign_file_left_alone() {
        let mut bytes = written(JOURNAL, &[b"one".to_vec()]);
        bytes[3] ^= 0x41;
        let (file, opened) = replay_memory(JOURNAL, bytes.clone());
        let replayed = opened.unwrap().1;
        assert_eq!((replayed.records.len(), replayed.discarded_bytes), (1, 8));
        assert!(file.contents().starts_with(JOURNAL.magic));
        // Two bits off, and nothing of ours after it: not ours.
        bytes.truncate(20);
        let (file, opened) = replay_memory(JOURNAL, bytes.clone());
        assert!(matches!(opened, Err(LogError::NotOurs("journal"))));
        assert_eq!(file.contents(), bytes);
        // Short and not a prefix of the magic: not ours either.
        let (_, opened) = replay_memory(JOURNAL, b"GOBYX".to_vec());
        assert!(matches!(opened, Err(LogError::NotOurs(_))));
        let (file, opened) = replay_memory(JOURNAL, b"GOBY".to_vec());
        assert_eq!(opened.unwrap().1.discarded_bytes, 4);
        assert_eq!(file.contents(), JOURNAL.magic);
    }

    #[test]
    fn a_rewrite_is_private_and_leaves_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("goby-record-log-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("records.log");
        let (mut log, _) = RecordLog::open(&path, INBOX, own).unwrap();
        log.append(b"gone").unwrap();
        log.rewrite([b"kept"]).unwrap();
        log.append(b"after").unwrap();
        log.sync().unwrap();
        drop(log);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        assert!(!crate::file::part_path(&path).exists());
        let (_, replayed) = RecordLog::open(&path, INBOX, own).unwrap();
        assert_eq!(replayed.records, [b"kept".to_vec(), b"after".to_vec()]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[cfg(unix)]
    #[test]
    fn a_failed_directory_sync_is_reported() {
        // A file whose directory cannot be synced (injected): the rewrite
        // is renamed in place, and the failure reported.
        let dir = std::env::temp_dir().join(format!("goby-record-log-dir-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        #[derive(Debug)]
        struct NoDirSync(File);
        impl LogFile for NoDirSync {
            fn read_all(&mut self) -> io::Result<Vec<u8>> {
                self.0.read_all()
            }
            fn write_at(&mut self, offset: u64, bytes: &[u8]) -> io::Result<()> {
                LogFile::write_at(&mut self.0, offset, bytes)
            }
            fn set_len(&mut self, len: u64) -> io::Result<()> {
                LogFile::set_len(&mut self.0, len)
            }
            fn sync(&mut self) -> io::Result<()> {
                self.0.sync()
            }
            fn sync_handle(&self) -> io::Result<File> {
                self.0.sync_handle()
            }
            fn reopen(&mut self, path: &Path) -> io::Result<()> {
                self.0.reopen(path)
            }
            fn sync_dir(&self, _: &Path) -> io::Result<()> {
                Err(io::Error::other("directory sync failed"))
            }
        }
        let path = dir.join("records.log");
        std::fs::write(&path, INBOX.magic).unwrap();
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .unwrap();
        let mut log = RecordLog::with_file(&path, INBOX, NoDirSync(file));
        let bytes = log.read_all().unwrap();
        log.replay(&bytes, own).unwrap();
        let err = log.rewrite([b"new"]).unwrap_err();
        assert!(err.to_string().contains("directory sync failed"), "{err}");
        // The new file is in place all the same, and appends go to it.
        log.append(b"more").unwrap();
        drop(log);
        let (_, replayed) = RecordLog::open(&path, INBOX, own).unwrap();
        assert_eq!(replayed.records, [b"new".to_vec(), b"more".to_vec()]);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A fault to apply to a written log.
    #[derive(Debug, Clone)]
    enum Fault {
        /// XOR these masks into the bytes at these positions (taken modulo
        /// the file's length).
        Flip(Vec<(usize, u8)>),
        /// Keep this many bytes (modulo the file's length + 1).
        Truncate(usize),
    }

    fn fault() -> impl Strategy<Value = Fault> {
        prop_oneof![
            proptest::collection::vec((any::<usize>(), 1..=255u8), 1..8).prop_map(Fault::Flip),
            any::<usize>().prop_map(Fault::Truncate),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        /// Written records, then bytes flipped or the file cut: replay never
        /// panics, returns written payloads only, in their order, accounts
        /// for every byte, and what it left replays to the same records.
        #[test]
        fn replay_of_a_damaged_log_returns_only_what_was_written(
            payloads in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..64), 0..12),
            inbox in any::<bool>(),
            fault in fault(),
        ) {
            let format = if inbox { INBOX } else { JOURNAL };
            let mut bytes = written(format, &payloads);
            let truncated = match &fault {
                Fault::Flip(flips) => {
                    let len = bytes.len();
                    for (at, mask) in flips {
                        bytes[at % len] ^= mask;
                    }
                    false
                }
                Fault::Truncate(keep) => {
                    bytes.truncate(keep % (bytes.len() + 1));
                    true
                }
            };
            let (file, opened) = replay_memory(format, bytes.clone());
            let Ok((mut log, replayed)) = opened else {
                // Not ours (a header too damaged): left untouched.
                prop_assert_eq!(file.contents(), bytes);
                return Ok(());
            };
            prop_assert!(
                is_subsequence(&replayed.records, &payloads),
                "replayed {:?} of {:?}", replayed.records, payloads
            );
            if truncated {
                // A cut costs the records it touches only.
                prop_assert!(payloads.starts_with(&replayed.records));
                prop_assert!(!replayed.rewrite_advised);
            }
            let kept: u64 = replayed.records.iter().map(|r| (FRAMING + r.len()) as u64).sum();
            // Every byte is the header, in a good record or discarded (a
            // damaged header counts as discarded).
            let len = bytes.len() as u64;
            if len < 8 {
                prop_assert!(replayed.records.is_empty());
                prop_assert_eq!(replayed.discarded_bytes, len);
            } else {
                let damaged_header = u64::from(!bytes.starts_with(format.magic)) * 8;
                prop_assert_eq!(8 + kept + replayed.discarded_bytes, len + damaged_header);
            }
            // Replayed again, the repaired file holds the same records; a
            // rewrite leaves nothing to discard.
            let (_, again) = replay_memory(format, file.contents());
            let again = again.expect("a repaired log opens").1;
            prop_assert_eq!(&again.records, &replayed.records);
            prop_assert_eq!(again.rewrite_advised, replayed.rewrite_advised);
            log.rewrite(&replayed.records).expect("rewritten in memory");
            log.append(b"after").expect("appended in memory");
            let (_, again) = replay_memory(format, file.contents());
            let again = again.expect("a rewritten log opens").1;
            prop_assert_eq!(again.discarded_bytes, 0);
            prop_assert_eq!(again.records.last().map(Vec::as_slice), Some(&b"after"[..]));
            prop_assert_eq!(&again.records[..again.records.len() - 1], &replayed.records[..]);
        }
    }
}
