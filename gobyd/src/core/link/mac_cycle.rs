//! A link's TDMA cycle as changed at sea (Goby3's `MACUpdate`, from MOOS
//! `MAC_CYCLE_UPDATE`, a JSON or MQTT request, or over the link), kept in
//! `DATA_DIR/mac_cycle` so that a restarted daemon runs the cycle it was
//! last given.
//!
//! The file is one protobuf-encoded `goby.acomms.protobuf.MACCycle`
//! (`protos/proto/goby/acomms/mac_update.proto`): the slots, whether the
//! cycle runs, the node's modem id, and the configured slots the changes
//! were made to. It is rewritten whole and durably (a new file synced,
//! renamed over the old, the directory synced) before a change takes
//! effect. At start it is used only when it was written for the same
//! modem id and the same configured cycle: a configuration edited since
//! runs as written.

use std::io;
use std::path::{Path, PathBuf};

use prost::Message;
use protos::goby::acomms::protobuf::{MacCycle, ModemTransmission};

/// Name of the file inside the data directory.
pub const FILE: &str = "mac_cycle";

/// Where a link's changed cycle is kept.
#[derive(Debug, Clone)]
pub struct MacCycleFile {
    path: PathBuf,
}

/// What the file at start says to run.
#[derive(Debug, Clone, PartialEq)]
pub enum Kept {
    /// No change was ever made: the configured cycle runs.
    Nothing,
    /// The changed cycle to run.
    Cycle(MacCycle),
    /// The file was written for another configuration (why, in words): the
    /// configured cycle runs.
    Stale(String),
}

impl MacCycleFile {
    /// The file in the data directory `dir`.
    pub fn in_dir(dir: &Path) -> Self {
        MacCycleFile {
            path: dir.join(FILE),
        }
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What to run at start for node `modem_id` configured with
    /// `configured` slots. Errors: the file cannot be read or does not
    /// decode (the error names the file).
    pub fn load(&self, modem_id: i32, configured: &[ModemTransmission]) -> io::Result<Kept> {
        let Some(cycle) = read_kept::<MacCycle>(&self.path)? else {
            return Ok(Kept::Nothing);
        };
        if cycle.modem_id() != modem_id {
            return Ok(Kept::Stale(format!(
                "it was written for modem {}, this node is modem {modem_id}",
                cycle.modem_id()
            )));
        }
        if cycle.configured_slot != configured {
            return Ok(Kept::Stale(
                "the configured cycle (mac.slot) changed since".into(),
            ));
        }
        Ok(Kept::Cycle(cycle))
    }

    /// Keeps `cycle` durably (see the module's documentation).
    pub fn save(&self, cycle: &MacCycle) -> io::Result<()> {
        keep(&self.path, cycle)
    }

    /// Forgets the changes (the configured cycle runs at the next start).
    pub fn remove(&self) -> io::Result<()> {
        match std::fs::remove_file(&self.path) {
            Err(e) if e.kind() != io::ErrorKind::NotFound => Err(named(&self.path, e)),
            _ => Ok(()),
        }
    }
}

/// The protobuf message kept at `path` (`None`: there is no file).
/// Errors: the file cannot be read or does not decode (the error names
/// the file).
pub(crate) fn read_kept<M: Message + Default>(path: &Path) -> io::Result<Option<M>> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(named(path, e)),
    };
    M::decode(bytes.as_slice()).map(Some).map_err(|e| {
        named(
            path,
            io::Error::new(io::ErrorKind::InvalidData, e.to_string()),
        )
    })
}

/// Writes `message` to `path` durably (a new file synced, renamed over
/// the old, the directory synced).
pub(crate) fn keep<M: Message>(path: &Path, message: &M) -> io::Result<()> {
    goby_store::file::write_atomically(path, &message.encode_to_vec()).map_err(|e| named(path, e))
}

fn named(path: &Path, e: io::Error) -> io::Error {
    io::Error::new(e.kind(), format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn slot(src: i32) -> ModemTransmission {
        ModemTransmission {
            src: Some(src),
            slot_seconds: Some(10.0),
            ..Default::default()
        }
    }

    fn temp_dir(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("gobyd-mac-cycle-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_kept_cycle_is_used_only_for_the_same_node_and_configuration() {
        let dir = temp_dir("kept");
        let file = MacCycleFile::in_dir(&dir);
        assert_eq!(file.load(2, &[slot(1)]).unwrap(), Kept::Nothing);
        let cycle = MacCycle {
            slot: vec![slot(2), slot(3)],
            running: Some(false),
            modem_id: Some(2),
            configured_slot: vec![slot(1)],
        };
        file.save(&cycle).unwrap();
        assert_eq!(file.load(2, &[slot(1)]).unwrap(), Kept::Cycle(cycle));
        assert!(
            matches!(file.load(3, &[slot(1)]).unwrap(), Kept::Stale(why) if why.contains("modem 2"))
        );
        assert!(
            matches!(file.load(2, &[slot(4)]).unwrap(), Kept::Stale(why) if why.contains("mac.slot"))
        );
    }

    #[test]
    fn a_damaged_file_is_an_error_naming_it() {
        let dir = temp_dir("damaged");
        let file = MacCycleFile::in_dir(&dir);
        std::fs::write(file.path(), [0xff, 0xff, 0xff]).unwrap();
        let err = file.load(2, &[]).unwrap_err().to_string();
        assert!(err.contains("mac_cycle"), "{err}");
    }
}
