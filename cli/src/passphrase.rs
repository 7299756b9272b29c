//! Where the DCCL passphrase of `goby dccl` comes from: the command line,
//! a file, or the environment.

use std::path::PathBuf;

use clap::Args;

use crate::CliError;

/// Environment variable read for the passphrase when no option gives one.
pub const PASSPHRASE_ENV: &str = "DCCL_PASSPHRASE";

/// The passphrase options of `goby dccl`. Without either option, a non-empty
/// `DCCL_PASSPHRASE` in the environment is used.
#[derive(Debug, Clone, Default, Args)]
pub struct PassphraseArgs {
    /// Encrypt or decrypt message bodies with this passphrase (key = SHA-256
    /// of it). Other local users can see it in the process list: prefer
    /// --passphrase-file or DCCL_PASSPHRASE.
    #[arg(long, value_name = "P", conflicts_with = "passphrase_file")]
    pub passphrase: Option<String>,
    /// Read the passphrase from this file (its whole content, one trailing
    /// line break removed). Without either option, a non-empty
    /// DCCL_PASSPHRASE in the environment is used.
    #[arg(long = "passphrase-file", value_name = "FILE")]
    pub passphrase_file: Option<PathBuf>,
}

impl PassphraseArgs {
    /// The passphrase to use, if any: `--passphrase`, then
    /// `--passphrase-file`, then `DCCL_PASSPHRASE`. An unreadable or empty
    /// file is an error.
    pub fn resolve(&self) -> Result<Option<String>, CliError> {
        if let Some(p) = &self.passphrase {
            if p.is_empty() {
                return Err(CliError::setup("--passphrase: the passphrase is empty"));
            }
            return Ok(Some(p.clone()));
        }
        if let Some(path) = &self.passphrase_file {
            let text = std::fs::read_to_string(path).map_err(|e| {
                CliError::setup(format!(
                    "{}: cannot read the passphrase file: {e}",
                    path.display()
                ))
            })?;
            let p = text
                .strip_suffix("\r\n")
                .or_else(|| text.strip_suffix('\n'))
                .unwrap_or(&text);
            if p.is_empty() {
                return Err(CliError::setup(format!(
                    "{}: the passphrase file is empty",
                    path.display()
                )));
            }
            return Ok(Some(p.to_string()));
        }
        match std::env::var(PASSPHRASE_ENV) {
            Ok(p) if !p.is_empty() => Ok(Some(p)),
            Ok(_) | Err(std::env::VarError::NotPresent) => Ok(None),
            Err(std::env::VarError::NotUnicode(_)) => Err(CliError::setup(format!(
                "{PASSPHRASE_ENV} is not valid UTF-8"
            ))),
        }
    }
}
