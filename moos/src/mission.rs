//! MOOS mission files (`.moos`): the global settings (`ServerHost`,
//! `ServerPort`, `Community`, `LatOrigin`, `LongOrigin`) and the inside of
//! one process's `ProcessConfig = NAME { ... }` block, as MOOS applications
//! read them.
//!
//! Every setting keeps the line it was written on, so that a value that
//! cannot be used is reported as `FILE:LINE`. The block is kept where it
//! stands in the file (blank lines before it, blanks in place of what
//! precedes its `{`), with `//` comments turned into `#`, so that a parser
//! of its inside (such as protobuf text format) reports the file's line and
//! column numbers.

use std::fmt;
use std::path::Path;

use crate::client::{DEFAULT_HOST, DEFAULT_PORT};

/// One `Key = value` line of a mission file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Setting {
    /// The value, trimmed, without a trailing `//` comment.
    pub value: String,
    /// Line it is written on, from 1.
    pub line: usize,
}

/// A mission file that cannot be read, with the line at fault.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MissionError {
    /// Line at fault, from 1 (0: the file as a whole).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl MissionError {
    fn at(line: usize, message: impl Into<String>) -> Self {
        MissionError {
            line,
            message: message.into(),
        }
    }

    /// The error as `ORIGIN:LINE: message` (`ORIGIN: message` without a line).
    pub fn located(&self, origin: &str) -> String {
        match self.line {
            0 => format!("{origin}: {}", self.message),
            line => format!("{origin}:{line}: {}", self.message),
        }
    }
}

impl fmt::Display for MissionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            0 => f.write_str(&self.message),
            line => write!(f, "line {line}: {}", self.message),
        }
    }
}

impl std::error::Error for MissionError {}

/// What a mission file holds for one process.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MissionFile {
    /// `ServerHost`.
    pub server_host: Option<Setting>,
    /// `ServerPort`.
    pub server_port: Option<Setting>,
    /// `Community`.
    pub community: Option<Setting>,
    /// `LatOrigin`, degrees.
    pub lat_origin: Option<Setting>,
    /// `LongOrigin`, degrees.
    pub long_origin: Option<Setting>,
    /// The inside of the process's block, placed at its line and column in
    /// the file (blanks before it), with `//` comments turned into `#`.
    pub process_config: Option<String>,
    /// Every line `KEY = value` outside the blocks (those above included),
    /// in the order of the file.
    pub globals: Vec<Global>,
}

/// A `KEY = value` line of a mission file outside every `ProcessConfig`
/// block.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Global {
    /// The key as written.
    pub key: String,
    /// The value, blanks at both ends and a `//` comment removed.
    pub value: String,
    /// Its line, from 1.
    pub line: usize,
}

/// `line` with a `//` comment outside quotes turned into `#`.
fn hash_comments(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut quote: Option<char> = None;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match quote {
            Some(q) => {
                out.push(c);
                if c == '\\' {
                    if let Some(n) = chars.next() {
                        out.push(n);
                    }
                } else if c == q {
                    quote = None;
                }
            }
            None if c == '"' || c == '\'' => {
                quote = Some(c);
                out.push(c);
            }
            None if c == '/' && chars.peek() == Some(&'/') => {
                // Same width, so that columns stay the file's.
                out.push('#');
                out.push(' ');
                chars.next();
            }
            None => out.push(c),
        }
    }
    out
}

/// The text of `line` before a `//` comment.
fn strip_comment(line: &str) -> &str {
    line.find("//").map_or(line, |p| &line[..p])
}

impl MissionFile {
    /// Reads the globals and the block of process `app` from the text of a
    /// mission file (an `app` with no block leaves
    /// [`process_config`](Self::process_config) unset). Every block must be
    /// closed; a second block of `app` is refused.
    pub fn parse(text: &str, app: &str) -> Result<Self, MissionError> {
        let mut mission = MissionFile::default();
        let lines: Vec<&str> = text.lines().collect();
        let mut i = 0;
        while i < lines.len() {
            let line = strip_comment(lines[i]).trim();
            let Some((key, value)) = line.split_once('=') else {
                i += 1;
                continue;
            };
            let (key, value) = (key.trim(), value.trim());
            if key.eq_ignore_ascii_case("ProcessConfig") {
                // The block: from its "{" to the matching "}".
                let is_ours = value.eq_ignore_ascii_case(app);
                let mut depth = 0usize;
                let mut started = false;
                let mut block = String::new();
                let mut j = i;
                'lines: while j < lines.len() {
                    let cleaned = hash_comments(lines[j]);
                    let mut quote: Option<char> = None;
                    let mut kept = String::new();
                    for (at, c) in cleaned.char_indices() {
                        let mut keep = started;
                        match quote {
                            Some(q) if c == q => quote = None,
                            Some(_) => {}
                            None if c == '#' => {
                                // The rest of the line is a comment.
                                kept.push_str(&cleaned[at..]);
                                break;
                            }
                            None if c == '"' || c == '\'' => quote = Some(c),
                            None if c == '{' => {
                                if !started {
                                    started = true;
                                    keep = false;
                                }
                                depth += 1;
                            }
                            None if c == '}' => {
                                depth = depth.saturating_sub(1);
                                if started && depth == 0 {
                                    block.push_str(&kept);
                                    block.push('\n');
                                    break 'lines;
                                }
                            }
                            None => {}
                        }
                        kept.push(if keep { c } else { ' ' });
                    }
                    // Keep the line numbering of the file.
                    if started {
                        block.push_str(&kept);
                    }
                    block.push('\n');
                    j += 1;
                }
                if !started || depth != 0 {
                    return Err(MissionError::at(
                        i + 1,
                        format!(
                            "ProcessConfig = {value} has no {{ ... }} block (or no closing }})"
                        ),
                    ));
                }
                if is_ours {
                    if mission.process_config.is_some() {
                        return Err(MissionError::at(
                            i + 1,
                            format!("a second ProcessConfig = {value} block"),
                        ));
                    }
                    let before = "\n".repeat(i);
                    mission.process_config = Some(before + &block);
                }
                i = j + 1;
                continue;
            }
            mission.globals.push(Global {
                key: key.to_string(),
                value: value.to_string(),
                line: i + 1,
            });
            let setting = Some(Setting {
                value: value.to_string(),
                line: i + 1,
            });
            match key.to_ascii_lowercase().as_str() {
                "serverhost" => mission.server_host = setting,
                "serverport" => mission.server_port = setting,
                "community" => mission.community = setting,
                "latorigin" => mission.lat_origin = setting,
                "longorigin" => mission.long_origin = setting,
                _ => {}
            }
            i += 1;
        }
        Ok(mission)
    }

    /// Reads the mission file at `path` as [`parse`](Self::parse) does;
    /// errors are `PATH:LINE: message`.
    pub fn read(path: &Path, app: &str) -> Result<Self, String> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read the mission file {origin}: {e}"))?;
        MissionFile::parse(&text, app).map_err(|e| e.located(&origin))
    }

    /// The global `key` (MOOS reads keys in any case).
    pub fn global(&self, key: &str) -> Option<&Global> {
        self.globals
            .iter()
            .find(|g| g.key.eq_ignore_ascii_case(key))
    }

    /// `ServerPort` as a TCP port, if set.
    pub fn port(&self) -> Result<Option<u16>, MissionError> {
        self.server_port
            .as_ref()
            .map(|s| {
                s.value
                    .parse::<u16>()
                    .ok()
                    .filter(|&p| p != 0)
                    .ok_or_else(|| {
                        MissionError::at(
                            s.line,
                            format!("ServerPort = {} is not a TCP port (1 to 65535)", s.value),
                        )
                    })
            })
            .transpose()
    }

    /// The MOOSDB's host and port: `ServerHost` and `ServerPort`, with
    /// MOOS's defaults (127.0.0.1, 9000) for those left out.
    pub fn server(&self) -> Result<(String, u16), MissionError> {
        let host = match &self.server_host {
            Some(s) if s.value.is_empty() || s.value.contains(char::is_whitespace) => {
                return Err(MissionError::at(
                    s.line,
                    format!("ServerHost = {} is not a host name or address", s.value),
                ))
            }
            Some(s) => s.value.clone(),
            None => DEFAULT_HOST.to_string(),
        };
        Ok((host, self.port()?.unwrap_or(DEFAULT_PORT)))
    }

    /// `LatOrigin` or `LongOrigin` (`setting`, named `what` in errors) as
    /// degrees, if set.
    pub fn degrees(setting: &Option<Setting>, what: &str) -> Result<Option<f64>, MissionError> {
        setting
            .as_ref()
            .map(|s| {
                s.value
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| {
                        MissionError::at(s.line, format!("{what} = {} is not a number", s.value))
                    })
            })
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MISSION: &str = r#"// Vehicle A
ServerHost = localhost
ServerPort = 9001   // the vehicle's DB
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
  format: "URL=http://x{y}#z" # {
}
"#;

    #[test]
    fn globals_keep_their_lines_and_the_block_its_place() {
        let mission = MissionFile::parse(MISSION, "gobyd").unwrap();
        assert_eq!(
            mission.server_port,
            Some(Setting {
                value: "9001".into(),
                line: 3
            })
        );
        assert_eq!(mission.community.as_ref().unwrap().value, "alpha");
        assert_eq!(mission.server().unwrap(), ("localhost".to_string(), 9001));
        assert_eq!(
            MissionFile::degrees(&mission.lat_origin, "LatOrigin").unwrap(),
            Some(42.358456)
        );
        let block = mission.process_config.unwrap();
        // `modem_id` stays at line 16, column 3; `//` became `#`; braces in
        // strings and comments do not count.
        let line16 = block.lines().nth(15).unwrap();
        assert_eq!(line16.find("modem_id"), Some(2), "{line16:?}");
        assert!(line16.contains("# "), "{line16:?}");
        assert!(block.contains(r#""URL=http://x{y}#z""#), "{block}");
        // Another process: no block, same globals.
        let other = MissionFile::parse(MISSION, "pHelmIvP").unwrap();
        assert_eq!(other.process_config, None);
        assert_eq!(other.server_host.unwrap().value, "localhost");
    }

    #[test]
    fn without_server_settings_the_defaults_of_moos() {
        let mission = MissionFile::parse("Community = x\n", "").unwrap();
        assert_eq!(mission.server().unwrap(), ("127.0.0.1".to_string(), 9000));
    }

    #[test]
    fn errors_name_the_line() {
        let err =
            MissionFile::parse("ProcessConfig = gobyd\n{\n modem_id: 1\n", "gobyd").unwrap_err();
        assert_eq!(err.line, 1);
        assert!(err.to_string().starts_with("line 1: "), "{err}");
        assert!(err.located("a.moos").starts_with("a.moos:1: "), "{err}");
        let twice = "ProcessConfig = a\n{\n}\nProcessConfig = a\n{\n}\n";
        let err = MissionFile::parse(twice, "a").unwrap_err();
        assert_eq!(err.line, 4, "{err}");
        for (text, line, needle) in [
            ("ServerPort = lots\n", 1, "ServerPort = lots"),
            ("\nServerPort = 70000\n", 2, "not a TCP port"),
            ("\n\nServerHost =\n", 3, "ServerHost"),
        ] {
            let err = MissionFile::parse(text, "").unwrap().server().unwrap_err();
            assert_eq!(err.line, line, "{text:?}: {err}");
            assert!(err.message.contains(needle), "{text:?}: {err}");
        }
        let mission = MissionFile::parse("x\nLatOrigin = north\n", "").unwrap();
        let err = MissionFile::degrees(&mission.lat_origin, "LatOrigin").unwrap_err();
        assert_eq!(err.to_string(), "line 2: LatOrigin = north is not a number");
    }
}
