//! `gobyd`'s configuration: one file in protobuf text format
//! (`goby.apps.protobuf.GobydConfig`), with defaults that run on a machine
//! with no modem.

use std::path::{Path, PathBuf};

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{
    driver_config, simulator_driver_config, DriverConfig, DriverType, MacConfig, MacType,
    ModemTransmission, QueueManagerConfig, QueuedMessageEntry, SimulatorDriverConfig,
};
use protos::goby::apps::protobuf::GobydConfig;

/// A commented configuration that works as it is: `gobyd --example-config`.
pub const EXAMPLE_CONFIG: &str = include_str!("example_config.pb.txt");

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The text is not a valid `GobydConfig`.
    #[error("{origin}: {reason}")]
    Parse {
        /// Where the text came from.
        origin: String,
        /// The parser's message (with line and column).
        reason: String,
    },
    /// A value is not usable.
    #[error("configuration: {0}")]
    Invalid(String),
}

/// Parses a configuration in protobuf text format; `origin` names it in
/// errors.
pub fn parse(text: &str, origin: &str) -> Result<GobydConfig, ConfigError> {
    let desc = GobydConfig::default().descriptor();
    let dynamic =
        DynamicMessage::parse_text_format(desc, text).map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            reason: e.to_string(),
        })?;
    dynamic
        .transcode_to::<GobydConfig>()
        .map_err(|e| ConfigError::Parse {
            origin: origin.to_string(),
            reason: e.to_string(),
        })
}

/// Reads and parses a configuration file.
pub fn load(path: &Path) -> Result<GobydConfig, ConfigError> {
    let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse(&text, &path.display().to_string())
}

/// The configuration with every section the daemon needs filled in: the
/// modem id copied where unset, the simulator driver and a fixed TDMA slot
/// of this node when none are given.
pub fn complete(mut config: GobydConfig) -> Result<GobydConfig, ConfigError> {
    let id = config.modem_id();
    if id <= 0 {
        return Err(ConfigError::Invalid(format!(
            "modem_id {id} is not valid: modem ids are 1 and up (0 is broadcast)"
        )));
    }
    let driver = config.driver.get_or_insert_with(|| DriverConfig {
        driver: Some(driver_config::Driver::DriverType(
            DriverType::DriverAcousticSimulator as i32,
        )),
        ..Default::default()
    });
    driver.modem_id.get_or_insert(id);
    let is_simulator = driver.driver
        == Some(driver_config::Driver::DriverType(
            DriverType::DriverAcousticSimulator as i32,
        ));
    if is_simulator && driver.simulator.is_none() {
        // One node at the origin of the in-process channel.
        driver.simulator = Some(SimulatorDriverConfig {
            node: vec![simulator_driver_config::NodePosition {
                modem_id: driver.modem_id(),
                ..Default::default()
            }],
            ..Default::default()
        });
    }
    let mac = config.mac.get_or_insert_with(|| MacConfig {
        r#type: Some(MacType::MacFixedDecentralized as i32),
        slot: vec![ModemTransmission {
            src: Some(id),
            dest: Some(-1),
            slot_seconds: Some(10.0),
            ..Default::default()
        }],
        ..Default::default()
    });
    mac.modem_id.get_or_insert(id);
    let queue = config.queue.get_or_insert_with(QueueManagerConfig::default);
    queue.modem_id.get_or_insert(id);
    Ok(config)
}

/// Queue entries for the loaded types that have none, with the defaults.
pub fn default_entries(queue: &mut QueueManagerConfig, loaded: &[String]) {
    for name in loaded {
        if !queue.message_entry.iter().any(|e| &e.protobuf_name == name) {
            queue.message_entry.push(QueuedMessageEntry {
                protobuf_name: name.clone(),
                ..Default::default()
            });
        }
    }
}

/// The loaded DCCL definitions.
#[derive(Debug)]
pub struct Definitions {
    /// The codec with every DCCL type loaded (clients publish these types).
    pub codec: dccl::Codec,
    /// Full names of the DCCL types loaded.
    pub loaded: Vec<String>,
}

/// Compiles and loads the configured `.proto` files (and the examples
/// unless `load_examples` is false).
pub fn load_definitions(config: &GobydConfig) -> Result<Definitions, ConfigError> {
    let dccl_config = config.dccl.clone().unwrap_or_default();
    let mut codec = dccl::Codec::new();
    if let Some(passphrase) = dccl_config.passphrase.as_deref() {
        codec.set_passphrase_with_exceptions(
            passphrase,
            dccl_config.skip_crypto_for_id.iter().copied(),
        );
    }
    let mut loaded = Vec::new();
    let pool = &protos::DESCRIPTOR_POOL;
    if dccl_config.load_examples() {
        for file in pool.files().filter(|f| f.package_name() == "goby.example") {
            loaded.extend(
                codec
                    .load_file_messages(pool, file.name())
                    .map_err(|e| ConfigError::Invalid(format!("example messages: {e}")))?,
            );
        }
    }
    if !dccl_config.proto_file.is_empty() {
        let files: Vec<PathBuf> = dccl_config.proto_file.iter().map(PathBuf::from).collect();
        let includes: Vec<PathBuf> = dccl_config.include_dir.iter().map(PathBuf::from).collect();
        for f in &files {
            if !f.is_file() {
                return Err(ConfigError::Invalid(format!(
                    "dccl.proto_file {}: no such file",
                    f.display()
                )));
            }
        }
        let user_pool = dccl::compile_protos(&files, &includes)
            .map_err(|e| ConfigError::Invalid(e.to_string()))?;
        for f in &files {
            let name = dccl::pool_file_name(&user_pool, f, &includes).ok_or_else(|| {
                ConfigError::Invalid(format!("{}: not found after compiling", f.display()))
            })?;
            loaded.extend(
                codec
                    .load_file_messages(&user_pool, &name)
                    .map_err(|e| ConfigError::Invalid(format!("{}: {e}", f.display())))?,
            );
        }
    }
    // Built-in types a translator entry names (goby.moos.example.NodeReport).
    for entry in &config.translator_entry {
        if loaded.contains(&entry.protobuf_name) {
            continue;
        }
        if let Some(desc) = pool.get_message_by_name(&entry.protobuf_name) {
            loaded.extend(
                codec
                    .load_file_messages(pool, desc.parent_file().name())
                    .map_err(|e| ConfigError::Invalid(format!("{}: {e}", entry.protobuf_name)))?,
            );
        }
    }
    loaded.sort();
    loaded.dedup();
    Ok(Definitions { codec, loaded })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_example_configuration_parses_and_completes() {
        let config = complete(parse(EXAMPLE_CONFIG, "example").unwrap()).unwrap();
        assert_eq!(config.modem_id(), 1);
        assert_eq!(config.driver.as_ref().unwrap().modem_id(), 1);
        assert!(config.json.is_some());
    }

    #[test]
    fn an_empty_configuration_runs_the_simulator_and_the_examples() {
        let config = complete(parse("", "empty").unwrap()).unwrap();
        assert_eq!(
            config.driver.as_ref().unwrap().driver,
            Some(driver_config::Driver::DriverType(
                DriverType::DriverAcousticSimulator as i32
            ))
        );
        assert_eq!(config.mac.as_ref().unwrap().slot[0].src(), 1);
        let defs = load_definitions(&config).unwrap();
        assert_eq!(
            defs.loaded,
            ["goby.example.Command", "goby.example.NavigationReport"]
        );
    }

    #[test]
    fn errors_name_the_place_and_the_value() {
        let err = parse("modem_id: \"two\"", "my.cfg")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("my.cfg:"), "{err}");
        let err = parse("no_such_field: 1", "my.cfg").unwrap_err().to_string();
        assert!(err.contains("no_such_field"), "{err}");
        let err = complete(parse("modem_id: 0", "x").unwrap())
            .unwrap_err()
            .to_string();
        assert!(err.contains("modem_id 0"), "{err}");
        let mut config = parse("dccl { proto_file: \"/no/such.proto\" }", "x").unwrap();
        config = complete(config).unwrap();
        let err = load_definitions(&config).unwrap_err().to_string();
        assert!(err.contains("/no/such.proto: no such file"), "{err}");
    }
}
