//! Which MAC of the switcher runs and until when, kept in
//! `DATA_DIR/mac_switch` so that a restarted daemon runs the same MAC
//! until the same keep-alive deadline (or goes back to the default when
//! the deadline passed while it was down).
//!
//! The file is one protobuf-encoded `goby.acomms.protobuf.MACSwitchState`
//! (`protos/proto/goby/acomms/mac_switch.proto`), rewritten whole and
//! durably before a switch takes effect (as `mac_cycle`). At start it is
//! used only when it was written for the same modem id and the same names
//! of MACs.

use std::io;
use std::path::{Path, PathBuf};

use protos::goby::acomms::protobuf::MacSwitchState;

use super::mac_cycle::{keep, read_kept};

/// Name of the file inside the data directory.
pub const FILE: &str = "mac_switch";

/// Where the switcher's state is kept.
#[derive(Debug, Clone)]
pub struct MacSwitchFile {
    path: PathBuf,
}

impl MacSwitchFile {
    /// The file in the data directory `dir`.
    pub fn in_dir(dir: &Path) -> Self {
        MacSwitchFile {
            path: dir.join(FILE),
        }
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The state kept for node `modem_id` with MACs `names`: `Ok(None)`
    /// when there is none; `Err` with why when it cannot be used (it
    /// cannot be read, does not decode, or was written for another node
    /// or other MACs).
    pub fn load(&self, modem_id: i32, names: &[String]) -> io::Result<Option<MacSwitchState>> {
        let Some(state) = read_kept::<MacSwitchState>(&self.path)? else {
            return Ok(None);
        };
        let stale = |why: String| {
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!("{}: not used ({why})", self.path.display()),
            )
        };
        if state.modem_id() != modem_id {
            return Err(stale(format!(
                "it was written for modem {}, this node is modem {modem_id}",
                state.modem_id()
            )));
        }
        if state.names != names {
            return Err(stale("the MACs of mac_switcher changed since".into()));
        }
        Ok(Some(state))
    }

    /// Keeps `state` durably.
    pub fn save(&self, state: &MacSwitchState) -> io::Result<()> {
        keep(&self.path, state)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kept_state_is_used_only_for_the_same_node_and_names() {
        let dir = std::env::temp_dir().join(format!("gobyd-mac-switch-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let file = MacSwitchFile::in_dir(&dir);
        let names = vec!["survey".to_string(), "quiet".to_string()];
        assert_eq!(file.load(2, &names).unwrap(), None);
        let state = MacSwitchState {
            active: Some("quiet".into()),
            keep_alive_until: Some(123),
            modem_id: Some(2),
            names: names.clone(),
        };
        file.save(&state).unwrap();
        assert_eq!(file.load(2, &names).unwrap(), Some(state));
        let err = file.load(3, &names).unwrap_err().to_string();
        assert!(
            err.contains("modem 2") && err.contains("mac_switch"),
            "{err}"
        );
        let err = file.load(2, &names[..1]).unwrap_err().to_string();
        assert!(err.contains("mac_switcher"), "{err}");
    }
}
