//! The daemon's log: standard error (under systemd, the journal, each line
//! with its priority) and, with `log { dir }` (pAcommsHandler's
//! `common { log_path }`), a file `DIR/gobyd.log` rotated by size, as text
//! or as JSON lines (`log { json }`, `--log-json`).
//!
//! Rotation: a line that would take `gobyd.log` past `log.max_file_bytes`
//! first renames it `gobyd.log.1` (the older ones move on to `.2`, ...,
//! the one past `log.max_files` removed) and starts a new `gobyd.log`, so
//! the log never takes more than `(max_files + 1) * max_file_bytes` of the
//! vehicle's disk. A daemon started again appends to the `gobyd.log` it
//! finds. A line that cannot be written (a full disk) is dropped, not
//! retried: the first such failure is told once on standard error, and
//! the next line written says how many were dropped.
//!
//! Under systemd (`JOURNAL_STREAM` naming standard error, as systemd sets
//! it for `StandardError=journal`), lines on standard error carry no time
//! (the journal stamps them) and start with their syslog priority (`<3>`
//! error, `<4>` warning, `<6>` info, `<7>` debug and trace), which the
//! journal reads: `journalctl -p warning` shows the warnings and errors.

use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use protos::goby::apps::protobuf::gobyd_config::LogConfig;
use protos::goby::apps::protobuf::GobydConfig;
use tracing::{Level, Metadata};
use tracing_subscriber::fmt::MakeWriter;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer, Registry};

/// The log file's name in `log.dir`.
pub const FILE_NAME: &str = "gobyd.log";

/// The smallest `log.max_file_bytes` taken.
pub const MIN_FILE_BYTES: u64 = 4096;

/// The problems of the `log` section that the start would refuse, each as
/// `log.FIELD: reason` (for `--check`): a level that is not a filter, a
/// directory that cannot be one, a file size under [`MIN_FILE_BYTES`].
pub fn problems(config: &GobydConfig) -> Vec<String> {
    let log = config.log.clone().unwrap_or_default();
    let mut out = Vec::new();
    if let Some(level) = &log.file_level {
        if let Some(problem) = crate::config::log_level_problem(level) {
            out.push(format!("log.file_level: {problem}"));
        }
    }
    if let Some(dir) = &log.dir {
        if let Some(problem) = dir_problem(Path::new(dir)) {
            out.push(format!("log.dir: {problem}"));
        }
    }
    if log.max_file_bytes() < MIN_FILE_BYTES {
        out.push(format!(
            "log.max_file_bytes: {} is too small a file for a log: give at least {MIN_FILE_BYTES}",
            log.max_file_bytes()
        ));
    }
    out
}

/// Why `dir` cannot be the log directory, if it is plain that it cannot:
/// it, or the nearest part of its path that exists, is not a directory.
fn dir_problem(dir: &Path) -> Option<String> {
    if dir.as_os_str().is_empty() {
        return Some("empty: give a directory (\".\" for the working directory)".into());
    }
    let existing = dir
        .ancestors()
        .find(|p| p.exists() || p.as_os_str().is_empty())?;
    if existing.as_os_str().is_empty() || existing.is_dir() {
        return None;
    }
    Some(if existing == dir {
        format!(
            "{:?} exists and is not a directory",
            dir.display().to_string()
        )
    } else {
        format!(
            "{:?} cannot be created: {:?} is not a directory",
            dir.display().to_string(),
            existing.display().to_string()
        )
    })
}

/// A log file rotated by size (see the [module](self)): `DIR/gobyd.log`,
/// then `gobyd.log.1` to `gobyd.log.N`.
#[derive(Debug)]
pub struct RotatingLog {
    dir: PathBuf,
    max_bytes: u64,
    keep: u32,
    state: Mutex<FileState>,
}

#[derive(Debug)]
struct FileState {
    file: Option<File>,
    /// Bytes in the current file.
    size: u64,
    /// Lines dropped since the last one written, and why the first was.
    dropped: u64,
    reason: String,
}

impl RotatingLog {
    /// Opens `dir/gobyd.log` for appending (the directory created if
    /// missing), to be rotated past `max_bytes` keeping `keep` full files.
    pub fn open(dir: &Path, max_bytes: u64, keep: u32) -> io::Result<RotatingLog> {
        std::fs::create_dir_all(dir)?;
        let log = RotatingLog {
            dir: dir.to_path_buf(),
            max_bytes: max_bytes.max(MIN_FILE_BYTES),
            keep,
            state: Mutex::new(FileState {
                file: None,
                size: 0,
                dropped: 0,
                reason: String::new(),
            }),
        };
        let file = log.open_current()?;
        let size = file.metadata()?.len();
        if let Ok(mut state) = log.state.lock() {
            state.file = Some(file);
            state.size = size;
        }
        Ok(log)
    }

    /// The path of the current file.
    pub fn path(&self) -> PathBuf {
        self.dir.join(FILE_NAME)
    }

    /// The path of full file `n` (1 the newest).
    pub fn rotated_path(&self, n: u32) -> PathBuf {
        self.dir.join(format!("{FILE_NAME}.{n}"))
    }

    /// Opens the current file, locked for this daemon: another `gobyd`
    /// writing its log into the same directory is refused (each needs its
    /// own `log.dir`).
    fn open_current(&self) -> io::Result<File> {
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(self.path())?;
        match file.try_lock() {
            Ok(()) => Ok(file),
            Err(std::fs::TryLockError::WouldBlock) => Err(io::Error::new(
                io::ErrorKind::ResourceBusy,
                "another gobyd writes its log there (give each its own log.dir)",
            )),
            Err(std::fs::TryLockError::Error(e)) => Err(e),
        }
    }

    /// Moves the full files on by one (the oldest removed) and the current
    /// one to `.1`, then opens a new current file.
    fn rotate(&self, state: &mut FileState) -> io::Result<()> {
        state.file = None;
        if self.keep == 0 {
            std::fs::remove_file(self.path())?;
        } else {
            let _ = std::fs::remove_file(self.rotated_path(self.keep));
            for n in (1..self.keep).rev() {
                let from = self.rotated_path(n);
                if from.exists() {
                    std::fs::rename(&from, self.rotated_path(n + 1))?;
                }
            }
            std::fs::rename(self.path(), self.rotated_path(1))?;
        }
        state.file = Some(self.open_current()?);
        state.size = 0;
        Ok(())
    }

    /// Writes one line (or several, whole), rotating first when it would
    /// take the file past its size.
    fn write_line(&self, state: &mut FileState, line: &[u8]) -> io::Result<()> {
        if state.file.is_none() {
            state.file = Some(self.open_current()?);
            state.size = state
                .file
                .as_ref()
                .map_or(Ok(0), |f| f.metadata().map(|m| m.len()))?;
        }
        let len = line.len() as u64;
        if state.size > 0 && state.size + len > self.max_bytes {
            self.rotate(state)?;
        }
        let file = state
            .file
            .as_mut()
            .ok_or_else(|| io::Error::other("no log file"))?;
        file.write_all(line)?;
        state.size += len;
        Ok(())
    }

    /// Writes `buf` (one event's lines), after a line telling how many were
    /// dropped before it if some were; a failure drops it and is told once
    /// on standard error.
    fn write_event(&self, buf: &[u8]) {
        let Ok(mut state) = self.state.lock() else {
            return;
        };
        if state.dropped > 0 {
            let note = format!(
                "gobyd: {} log line(s) dropped: {}\n",
                state.dropped, state.reason
            );
            if self.write_line(&mut state, note.as_bytes()).is_err() {
                state.dropped += 1;
                return;
            }
            state.dropped = 0;
        }
        if let Err(e) = self.write_line(&mut state, buf) {
            if state.dropped == 0 {
                state.reason = format!("cannot write {}: {e}", self.path().display());
                eprintln!(
                    "gobyd: warning: {}: log lines are dropped until it can",
                    state.reason
                );
            }
            state.dropped += 1;
        }
    }
}

/// One event's text for the [`RotatingLog`], written whole when dropped.
#[derive(Debug)]
pub struct RotatingLogWriter<'a> {
    log: &'a RotatingLog,
    buf: Vec<u8>,
}

impl Write for RotatingLogWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.buf.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Drop for RotatingLogWriter<'_> {
    fn drop(&mut self) {
        if !self.buf.is_empty() {
            self.log.write_event(&self.buf);
        }
    }
}

impl<'a> MakeWriter<'a> for RotatingLog {
    type Writer = RotatingLogWriter<'a>;
    fn make_writer(&'a self) -> Self::Writer {
        RotatingLogWriter {
            log: self,
            buf: Vec::new(),
        }
    }
}

/// Whether standard error goes to the systemd journal: `JOURNAL_STREAM`
/// (`DEVICE:INODE`) names the file standard error is.
pub fn stderr_is_journal() -> bool {
    let Ok(stream) = std::env::var("JOURNAL_STREAM") else {
        return false;
    };
    stderr_identity().is_some_and(|(dev, ino)| stream == format!("{dev}:{ino}"))
}

#[cfg(unix)]
fn stderr_identity() -> Option<(u64, u64)> {
    use std::os::fd::AsFd;
    use std::os::unix::fs::MetadataExt;
    let fd = io::stderr().as_fd().try_clone_to_owned().ok()?;
    let meta = File::from(fd).metadata().ok()?;
    Some((meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn stderr_identity() -> Option<(u64, u64)> {
    None
}

/// The syslog priority prefix of a level, as the journal reads it.
fn priority(level: &Level) -> &'static [u8] {
    match *level {
        Level::ERROR => b"<3>",
        Level::WARN => b"<4>",
        Level::INFO => b"<6>",
        _ => b"<7>",
    }
}

/// Standard error with each line of an event prefixed by its priority
/// (for the journal).
#[derive(Debug, Default)]
pub struct JournalStderr;

/// One event's text for [`JournalStderr`].
#[derive(Debug)]
pub struct JournalLine {
    prefix: &'static [u8],
    buf: Vec<u8>,
}

impl Write for JournalLine {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.buf.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

impl Drop for JournalLine {
    fn drop(&mut self) {
        let _ = io::stderr()
            .lock()
            .write_all(&prefixed(self.prefix, &self.buf));
    }
}

/// `text` with `prefix` at the start of each of its lines.
fn prefixed(prefix: &[u8], text: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(text.len() + prefix.len());
    for line in text.split_inclusive(|&b| b == b'\n') {
        out.extend_from_slice(prefix);
        out.extend_from_slice(line);
    }
    out
}

impl<'a> MakeWriter<'a> for JournalStderr {
    type Writer = JournalLine;
    fn make_writer(&'a self) -> Self::Writer {
        JournalLine {
            prefix: b"<6>",
            buf: Vec::new(),
        }
    }
    fn make_writer_for(&'a self, meta: &Metadata<'_>) -> Self::Writer {
        JournalLine {
            prefix: priority(meta.level()),
            buf: Vec::new(),
        }
    }
}

/// The level filter of `level` (an invalid one told on standard error and
/// taken as info).
fn filter(level: &str, what: &str) -> EnvFilter {
    match crate::config::log_level_problem(level) {
        Some(problem) => {
            eprintln!("gobyd: {what}: {problem}; logging at info");
            EnvFilter::new("info")
        }
        None => EnvFilter::try_new(level).unwrap_or_else(|_| EnvFilter::new("info")),
    }
}

type BoxedLayer = Box<dyn Layer<Registry> + Send + Sync>;

/// The layer writing to `writer`, as text or JSON lines, with or without
/// time and colours.
fn layer<W>(writer: W, json: bool, time: bool, ansi: bool) -> BoxedLayer
where
    W: for<'w> MakeWriter<'w> + Send + Sync + 'static,
{
    let base = tracing_subscriber::fmt::layer()
        .with_writer(writer)
        .with_ansi(ansi);
    match (json, time) {
        (true, true) => base.json().boxed(),
        (true, false) => base.json().without_time().boxed(),
        (false, true) => base.boxed(),
        (false, false) => base.without_time().boxed(),
    }
}

/// Sets up the daemon's log as `config.log` says (see the
/// [module](self)); the error names the log file that cannot be opened.
/// Does nothing when a logger is already set (a test's, a program's that
/// embeds the daemon).
pub fn init(config: &GobydConfig) -> Result<(), String> {
    let log: LogConfig = config.log.clone().unwrap_or_default();
    let stderr_layer = if stderr_is_journal() {
        layer(JournalStderr, log.json(), log.json(), false)
    } else {
        use std::io::IsTerminal;
        let ansi = io::stderr().is_terminal();
        layer(io::stderr, log.json(), true, ansi)
    };
    let mut layers = vec![stderr_layer
        .with_filter(filter(log.level(), "log.level"))
        .boxed()];
    if let Some(dir) = &log.dir {
        let file = RotatingLog::open(Path::new(dir), log.max_file_bytes(), log.max_files())
            .map_err(|e| format!("log.dir: cannot open {}/{FILE_NAME}: {e}", dir))?;
        let level = log.file_level.as_deref().unwrap_or(log.level());
        layers.push(
            layer(file, log.json(), true, false)
                .with_filter(filter(level, "log.file_level"))
                .boxed(),
        );
    }
    let _ = tracing_subscriber::registry().with(layers).try_init();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("gobyd-logging-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    fn line(n: usize) -> Vec<u8> {
        format!("{n:0>99}\n").into_bytes()
    }

    /// Past its size the file moves to .1 and the full ones on; no file
    /// passes the size, none past `keep` is kept, and the lines read back
    /// whole and in order, oldest file first.
    #[test]
    fn rotates_by_size_and_keeps_the_newest_files() {
        let dir = scratch("rotate");
        let log = RotatingLog::open(&dir, 4096, 2).unwrap();
        for n in 0..200 {
            log.write_event(&line(n));
        }
        let sizes: Vec<u64> = [log.rotated_path(2), log.rotated_path(1), log.path()]
            .iter()
            .map(|p| std::fs::metadata(p).unwrap().len())
            .collect();
        assert!(sizes.iter().all(|&s| s <= 4096), "{sizes:?}");
        assert!(!log.rotated_path(3).exists());
        let text: String = [log.rotated_path(2), log.rotated_path(1), log.path()]
            .iter()
            .map(|p| std::fs::read_to_string(p).unwrap())
            .collect();
        let numbers: Vec<usize> = text.lines().map(|l| l.parse().unwrap()).collect();
        // 40 lines of 100 bytes fill a file: the newest three files hold
        // the last 120 lines, in order.
        assert_eq!(numbers, (80..200).collect::<Vec<_>>());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A daemon started again appends to the file it finds, rotating it at
    /// the same size.
    #[test]
    fn appends_to_the_file_it_finds() {
        let dir = scratch("append");
        {
            let log = RotatingLog::open(&dir, 4096, 1).unwrap();
            for n in 0..30 {
                log.write_event(&line(n));
            }
        }
        let log = RotatingLog::open(&dir, 4096, 1).unwrap();
        for n in 30..45 {
            log.write_event(&line(n));
        }
        let old = std::fs::read_to_string(log.rotated_path(1)).unwrap();
        let new = std::fs::read_to_string(log.path()).unwrap();
        assert_eq!(old.lines().count(), 40);
        assert_eq!(new.lines().next().unwrap().parse::<usize>().unwrap(), 40);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// With no full file kept, a full file is removed.
    #[test]
    fn keeps_no_full_file_when_told() {
        let dir = scratch("none");
        let log = RotatingLog::open(&dir, 4096, 0).unwrap();
        for n in 0..45 {
            log.write_event(&line(n));
        }
        assert!(!log.rotated_path(1).exists());
        assert_eq!(
            std::fs::read_to_string(log.path()).unwrap().lines().count(),
            5
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A second log on the same directory is refused while the first is
    /// open (two daemons with one log_path).
    #[test]
    fn one_daemon_a_directory() {
        let dir = scratch("lock");
        let first = RotatingLog::open(&dir, 4096, 1).unwrap();
        let second = RotatingLog::open(&dir, 4096, 1).unwrap_err();
        assert!(second.to_string().contains("another gobyd"), "{second}");
        drop(first);
        RotatingLog::open(&dir, 4096, 1).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A line that cannot be written is dropped and counted; the next one
    /// written says how many were.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_line_that_cannot_be_written_is_counted() {
        let dir = scratch("full");
        let log = RotatingLog::open(&dir, 4096, 1).unwrap();
        {
            // /dev/full: every write fails with ENOSPC, as a full disk.
            let mut state = log.state.lock().unwrap();
            state.file = Some(OpenOptions::new().write(true).open("/dev/full").unwrap());
        }
        log.write_event(b"lost 1\n");
        log.write_event(b"lost 2\n");
        {
            let mut state = log.state.lock().unwrap();
            state.file = None;
        }
        log.write_event(b"kept\n");
        let text = std::fs::read_to_string(log.path()).unwrap();
        assert!(
            text.contains("2 log line(s) dropped: cannot write"),
            "{text}"
        );
        assert!(text.ends_with("kept\n"), "{text}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn each_line_of_an_event_gets_its_priority() {
        assert_eq!(prefixed(b"<4>", b"a\nb\n"), b"<4>a\n<4>b\n");
        assert_eq!(prefixed(b"<3>", b"one"), b"<3>one");
    }

    #[test]
    fn problems_name_the_field() {
        let mut config = GobydConfig::default();
        let file = std::env::temp_dir().join(format!("gobyd-logging-file-{}", std::process::id()));
        std::fs::write(&file, "").unwrap();
        config.log = Some(LogConfig {
            dir: Some(file.join("logs").display().to_string()),
            file_level: Some("loud".into()),
            max_file_bytes: Some(100),
            ..Default::default()
        });
        let problems = problems(&config);
        assert_eq!(problems.len(), 3, "{problems:?}");
        assert!(problems[0].starts_with("log.file_level: "));
        assert!(problems[1].starts_with("log.dir: ") && problems[1].contains("is not a directory"));
        assert!(problems[2].starts_with("log.max_file_bytes: 100 "));
        let _ = std::fs::remove_file(&file);
    }
}
