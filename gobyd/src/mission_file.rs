//! `gobyd`'s configuration from a MOOS mission file (`.moos`), as a Goby
//! MOOS application such as pAcommsHandler reads its own: the global
//! `ServerHost`, `ServerPort`, `Community`, `LatOrigin` and `LongOrigin`,
//! and the `ProcessConfig = gobyd { ... }` block, whose inside is the
//! configuration in protobuf text format (`//` comments allowed, as in the
//! rest of the file).
//!
//! The globals fill the `moos` section where the block leaves it unset
//! (server, port, lat_origin, lon_origin), and pAcommsHandler's variables
//! (`moos_var`) are written with their default names unless the block
//! configures them. The block is parsed where it stands in the file, so
//! line and column numbers in errors are the mission file's.

use std::path::Path;

use protos::goby::apps::protobuf::GobydConfig;

pub use moos::mission::MissionFile;

use crate::config::{self, ConfigError};

/// `gobyd`'s configuration from a parsed mission file: the block of
/// process `app` (named `origin` in errors) with the globals filled in.
pub fn configuration(
    mission: &MissionFile,
    origin: &str,
    app: &str,
) -> Result<GobydConfig, ConfigError> {
    let block = mission
        .process_config
        .as_deref()
        .ok_or_else(|| ConfigError::Invalid(format!("{origin}: no ProcessConfig = {app} block")))?;
    let mut config = config::parse(block, origin)?;
    let invalid = |e: moos::mission::MissionError| ConfigError::Invalid(e.located(origin));
    let lat = MissionFile::degrees(&mission.lat_origin, "LatOrigin").map_err(invalid)?;
    let lon = MissionFile::degrees(&mission.long_origin, "LongOrigin").map_err(invalid)?;
    let port = mission.port().map_err(invalid)?;
    let moos = config.moos.get_or_insert_with(Default::default);
    if moos.server.is_none() {
        moos.server = mission.server_host.as_ref().map(|s| s.value.clone());
    }
    if moos.port.is_none() {
        moos.port = port.map(u32::from);
    }
    if moos.name.is_none() {
        moos.name = Some(app.to_string());
    }
    if moos.lat_origin.is_none() {
        moos.lat_origin = lat;
    }
    if moos.lon_origin.is_none() {
        moos.lon_origin = lon;
    }
    config.moos_var.get_or_insert_with(Default::default);
    Ok(config)
}

/// Reads `gobyd`'s configuration from the mission file at `path`, from the
/// block of process `app` (`gobyd` unless pAntler gives another name).
pub fn load(path: &Path, app: &str) -> Result<GobydConfig, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let origin = path.display().to_string();
    let mission =
        MissionFile::parse(&text, app).map_err(|e| ConfigError::Invalid(e.located(&origin)))?;
    configuration(&mission, &origin, app)
}

#[cfg(test)]
mod tests {
    use super::*;

    const MISSION: &str = r#"// Vehicle A
ServerHost = localhost
ServerPort = 9001
Community  = alpha
LatOrigin  = 42.358456
LongOrigin = -71.087589

ProcessConfig = ANTLER
{
  Run = MOOSDB @ NewConsole = false
  Run = gobyd  @ NewConsole = false
}

ProcessConfig = gobyd   // the acoustic link
{
  modem_id: 1   // this vehicle
  dccl { load_examples: false }  // only the NodeReport
  translator_entry {
    protobuf_name: "goby.moos.example.NodeReport"
    trigger { type: TRIGGER_PUBLISH moos_var: "NODE_REPORT_LOCAL" }
    create { technique: TECHNIQUE_COMMA_SEPARATED_KEY_EQUALS_VALUE_PAIRS moos_var: "NODE_REPORT_LOCAL" }
    publish { technique: TECHNIQUE_FORMAT moos_var: "NODE_REPORT" format: "NAME=%1%,URL=http://x{y}#z" } # {
  }
}
"#;

    #[test]
    fn globals_and_the_block_make_the_configuration() {
        let mission = MissionFile::parse(MISSION, "gobyd").unwrap();
        let config = configuration(&mission, "a.moos", "gobyd").unwrap();
        assert_eq!(config.modem_id(), 1);
        let moos = config.moos.as_ref().unwrap();
        assert_eq!(
            (moos.server(), moos.port(), moos.name()),
            ("localhost", 9001, "gobyd")
        );
        assert_eq!(moos.lat_origin, Some(42.358456));
        assert_eq!(moos.lon_origin, Some(-71.087589));
        assert!(config.moos_var.is_some());
        // "//" inside a string is kept; braces inside strings do not count.
        assert_eq!(
            config.translator_entry[0].publish[0].format(),
            "NAME=%1%,URL=http://x{y}#z"
        );
    }

    #[test]
    fn errors_point_into_the_mission_file() {
        let bad = MISSION.replace("modem_id: 1", "modem_id: one");
        let mission = MissionFile::parse(&bad, "gobyd").unwrap();
        let err = configuration(&mission, "a.moos", "gobyd")
            .unwrap_err()
            .to_string();
        // The block keeps the file's lines and columns: `modem_id` is at
        // line 16, column 3.
        assert!(
            err.starts_with("a.moos:16:") && err.contains("'one'"),
            "{err}"
        );
        let mission = MissionFile::parse(MISSION, "other").unwrap();
        let err = configuration(&mission, "a.moos", "other")
            .unwrap_err()
            .to_string();
        assert!(err.contains("no ProcessConfig = other block"), "{err}");
        let bad = MISSION.replace("ServerPort = 9001", "ServerPort = lots");
        let mission = MissionFile::parse(&bad, "gobyd").unwrap();
        let err = configuration(&mission, "a.moos", "gobyd")
            .unwrap_err()
            .to_string();
        assert!(err.contains("a.moos:3: ServerPort = lots"), "{err}");
    }
}
