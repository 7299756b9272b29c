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
//!
//! A pAcommsHandler block pastes in as it is: its Goby keys are read as
//! [`config::goby`] says, and MOOS `KEY = value` lines among the protobuf
//! text are read too ([`Layout::MissionBlock`]). An initializer reading a
//! global (`common { initializer { global_cfg_var: "LatOrigin" ... } }`)
//! takes its value from the file's globals, the global
//! `modem_id_lookup_path` is read where the block gives none, and the
//! globals gobyd cannot follow are refused: a `MOOSTimeWarp` other than 1
//! (gobyd runs on the real clock), `use_binary_protobuf = true` or another
//! `moos_parser_technique` (gobyd writes `@PB[Name] text format`).

use std::path::Path;

use protos::goby::apps::protobuf::gobyd_config::moos_interface::initializer::Type as InitializerType;
use protos::goby::apps::protobuf::GobydConfig;

pub use moos::mission::{Global, MissionFile};

use crate::config::{self, ConfigError, Layout, Problem};

/// `gobyd`'s configuration from a parsed mission file: the block of
/// process `app` (named `origin` in errors) with the globals filled in;
/// its notes ([`config::Read`]) are logged.
pub fn configuration(
    mission: &MissionFile,
    origin: &str,
    app: &str,
) -> Result<GobydConfig, ConfigError> {
    let read = read_mission(mission, origin, app)?;
    read.log_notes();
    Ok(read.config)
}

/// `gobyd`'s configuration as [`configuration`] gives it, with its notes
/// and where each field is written.
pub fn read_mission(
    mission: &MissionFile,
    origin: &str,
    app: &str,
) -> Result<config::Read, ConfigError> {
    let block = mission
        .process_config
        .as_deref()
        .ok_or_else(|| ConfigError::Invalid(format!("{origin}: no ProcessConfig = {app} block")))?;
    if let Some(warp) = mission.global("MOOSTimeWarp") {
        if warp.value.parse::<f64>().ok() != Some(1.0) {
            return Err(ConfigError::Invalid(format!(
                "{origin}:{}: MOOSTimeWarp = {}: gobyd runs on the real clock (its slots and timeouts are real seconds): \
                 remove MOOSTimeWarp or make it 1 to run gobyd in this mission",
                warp.line, warp.value
            )));
        }
    }
    // Globals Goby's MOOS applications read that change what they write.
    if let Some(binary) = mission.global("use_binary_protobuf") {
        if !binary.value.eq_ignore_ascii_case("false") {
            return Err(ConfigError::Invalid(format!(
                "{origin}:{}: use_binary_protobuf = {}: gobyd writes protobuf messages to MOOS variables \
                 as \"@PB[Name] text format\" only: remove it or make it false",
                binary.line, binary.value
            )));
        }
    }
    if let Some(technique) = mission.global("moos_parser_technique") {
        if technique.value != "TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT" {
            return Err(ConfigError::Invalid(format!(
                "{origin}:{}: moos_parser_technique = {}: gobyd writes protobuf messages to MOOS variables \
                 as \"@PB[Name] text format\" (TECHNIQUE_PREFIXED_PROTOBUF_TEXT_FORMAT) only: remove it",
                technique.line, technique.value
            )));
        }
    }
    let mut read = config::read(block, origin, Layout::MissionBlock)?;
    let config = &mut read.config;
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
    if config.modem_id_lookup_path.is_none() {
        config.modem_id_lookup_path = mission
            .global("modem_id_lookup_path")
            .map(|g| g.value.clone());
    }
    let mut problems = Vec::new();
    for (i, ini) in moos.initializer.iter_mut().enumerate() {
        let Some(key) = ini.global_cfg_var.take() else {
            continue;
        };
        let field = format!("moos.initializer[{i}].global_cfg_var");
        let Some(global) = mission.global(&key) else {
            problems.push(Problem::new(
                field,
                format!("{key:?} is not a global of the mission file (a KEY = value line outside the ProcessConfig blocks)"),
            ));
            continue;
        };
        match ini.r#type() {
            InitializerType::IniDouble => match global.value.parse::<f64>() {
                Ok(value) => ini.dval = Some(value),
                Err(_) => problems.push(Problem::new(
                    field,
                    format!(
                        "{key} = {} (line {}) is not a number, and the initializer is INI_DOUBLE (INI_STRING writes it as a string)",
                        global.value, global.line
                    ),
                )),
            },
            InitializerType::IniString => ini.sval = Some(global.value.clone()),
        }
    }
    config.moos_var.get_or_insert_with(Default::default);
    if !problems.is_empty() {
        read.locate(&mut problems);
        return Err(ConfigError::Problems(problems));
    }
    Ok(read)
}

/// Reads `gobyd`'s configuration from the mission file at `path`, from the
/// block of process `app` (`gobyd` unless pAntler gives another name); its
/// notes are logged.
pub fn load(path: &Path, app: &str) -> Result<GobydConfig, ConfigError> {
    let read = read(path, app)?;
    read.log_notes();
    Ok(read.config)
}

/// [`load`], with the configuration's notes and where each field is
/// written (to locate the problems the checks find).
pub fn read(path: &Path, app: &str) -> Result<config::Read, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let origin = path.display().to_string();
    let mission =
        MissionFile::parse(&text, app).map_err(|e| ConfigError::Invalid(e.located(&origin)))?;
    read_mission(&mission, &origin, app)
}

/// The process whose block is read when the command line names none.
pub const DEFAULT_APP: &str = "gobyd";

/// The block read instead when the mission file has no
/// `ProcessConfig = gobyd`: pAcommsHandler's, which gobyd replaces.
pub const PACOMMS_APP: &str = "pAcommsHandler";

/// Reads `gobyd`'s configuration from the mission file at `path` when no
/// process name is given (`--moos-file FILE`, `gobyd FILE`): the block
/// `ProcessConfig = gobyd`, or, with none, `ProcessConfig = pAcommsHandler`
/// (a note then says which block was read; the MOOS name stays `gobyd`).
/// With neither, the error names both.
pub fn read_default(path: &Path) -> Result<config::Read, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let origin = path.display().to_string();
    let parse = |app: &str| {
        MissionFile::parse(&text, app).map_err(|e| ConfigError::Invalid(e.located(&origin)))
    };
    let mission = parse(DEFAULT_APP)?;
    if mission.process_config.is_some() {
        return read_mission(&mission, &origin, DEFAULT_APP);
    }
    let mission = parse(PACOMMS_APP)?;
    if mission.process_config.is_none() {
        return Err(ConfigError::Invalid(format!(
            "{origin}: no ProcessConfig = {DEFAULT_APP} block, nor a ProcessConfig = {PACOMMS_APP} block to read instead"
        )));
    }
    let mut read = read_mission(&mission, &origin, DEFAULT_APP)?;
    read.notes.insert(
        0,
        config::Note {
            level: config::NoteLevel::Info,
            place: Some(origin),
            text: format!(
                "no ProcessConfig = {DEFAULT_APP} block: read the ProcessConfig = {PACOMMS_APP} block"
            ),
        },
    );
    Ok(read)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Method syntax for the tests: `mission.configuration(origin, app)`.
    trait Configure {
        fn configuration(&self, origin: &str, app: &str) -> Result<GobydConfig, ConfigError>;
    }

    impl Configure for MissionFile {
        fn configuration(&self, origin: &str, app: &str) -> Result<GobydConfig, ConfigError> {
            super::configuration(self, origin, app)
        }
    }

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
        assert_eq!(
            mission.server_port.as_ref().map(|s| &s.value[..]),
            Some("9001")
        );
        assert_eq!(
            mission.community.as_ref().map(|s| &s.value[..]),
            Some("alpha")
        );
        let config = mission.configuration("a.moos", "gobyd").unwrap();
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
    fn goby_globals_are_read_or_refused() {
        let with = |global: &str| MISSION.replace("Community  = alpha", global);
        let config = MissionFile::parse(&with("modem_id_lookup_path = ids.txt"), "gobyd")
            .unwrap()
            .configuration("a.moos", "gobyd")
            .unwrap();
        assert_eq!(config.modem_id_lookup_path(), "ids.txt");
        for (global, says) in [
            (
                "MOOSTimeWarp = 5",
                "a.moos:4: MOOSTimeWarp = 5: gobyd runs on the real clock",
            ),
            (
                "use_binary_protobuf = true",
                "a.moos:4: use_binary_protobuf = true",
            ),
            (
                "moos_parser_technique = TECHNIQUE_PREFIXED_PROTOBUF_NATIVE_HEX",
                "a.moos:4: moos_parser_technique = TECHNIQUE_PREFIXED_PROTOBUF_NATIVE_HEX",
            ),
        ] {
            let e = MissionFile::parse(&with(global), "gobyd")
                .unwrap()
                .configuration("a.moos", "gobyd")
                .unwrap_err()
                .to_string();
            assert!(e.contains(says), "{global}: {e}");
        }
        for fine in ["MOOSTimeWarp = 1", "use_binary_protobuf = false"] {
            MissionFile::parse(&with(fine), "gobyd")
                .unwrap()
                .configuration("a.moos", "gobyd")
                .unwrap();
        }
    }

    #[test]
    fn errors_point_into_the_mission_file() {
        let bad = MISSION.replace("modem_id: 1", "modem_id: one");
        let err = MissionFile::parse(&bad, "gobyd")
            .unwrap()
            .configuration("a.moos", "gobyd")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("a.moos:") && err.contains("'one'"), "{err}");
        // The block keeps the file's lines and columns, so that positions
        // in parse errors are the file's: `modem_id` is at line 16, column 3.
        let block = MissionFile::parse(MISSION, "gobyd")
            .unwrap()
            .process_config
            .unwrap();
        let line16 = block.lines().nth(15).unwrap();
        assert_eq!(line16.find("modem_id"), Some(2), "{line16:?}");
        let err = MissionFile::parse(MISSION, "other")
            .unwrap()
            .configuration("a.moos", "other")
            .unwrap_err()
            .to_string();
        assert!(err.contains("no ProcessConfig = other block"), "{err}");
        let err =
            MissionFile::parse("ProcessConfig = gobyd\n{\n modem_id: 1\n", "gobyd").unwrap_err();
        assert!(err.to_string().contains("line 1"), "{err}");
        let bad = MISSION.replace("ServerPort = 9001", "ServerPort = lots");
        let err = MissionFile::parse(&bad, "gobyd")
            .unwrap()
            .configuration("a.moos", "gobyd")
            .unwrap_err()
            .to_string();
        assert!(err.contains("a.moos:3: ServerPort = lots"), "{err}");
    }
}
