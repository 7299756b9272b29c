//! The modem-id lookup file of Goby (`modem_id_lookup_path`): one vehicle
//! a line as `modem_id, name, type[, location name]`; blanks are ignored,
//! `#` and `//` start comments, blank lines are skipped.
//!
//! ```text
//! // modem id, vehicle name, vehicle type
//! 1, resolution, ship
//! 3, unicorn, auv
//! ```

use std::collections::BTreeMap;
use std::path::Path;

/// The vehicles of a lookup file by modem id.
#[derive(Debug, Clone, Default)]
pub struct ModemIdLookup {
    names: BTreeMap<i32, String>,
    types: BTreeMap<i32, String>,
}

impl ModemIdLookup {
    /// Reads a lookup file; errors name the file and line.
    pub fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| format!("{}:{e}", path.display()))
    }

    /// Parses the text of a lookup file; an error starts with the line
    /// number.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut lookup = ModemIdLookup::default();
        for (n, line) in text.lines().enumerate() {
            let mut line: String = line.chars().filter(|c| *c != ' ' && *c != '\t').collect();
            if let Some(p) = line.find('#') {
                line.truncate(p);
            }
            if let Some(p) = line.find("//") {
                line.truncate(p);
            }
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let parts: Vec<&str> = line.split(',').collect();
            if parts.len() < 3 {
                return Err(format!(
                    "{}: {line:?} is not \"modem_id, name, type\"",
                    n + 1
                ));
            }
            let id: i32 = parts[0]
                .parse()
                .map_err(|_| format!("{}: modem id {:?} is not a number", n + 1, parts[0]))?;
            lookup.names.insert(id, parts[1].to_string());
            lookup.types.insert(id, parts[2].to_string());
        }
        Ok(lookup)
    }

    /// The name of modem `id` (the id itself when it is not in the file).
    pub fn name(&self, id: i32) -> String {
        self.names
            .get(&id)
            .cloned()
            .unwrap_or_else(|| id.to_string())
    }

    /// The type of modem `id` (`unknown_type` when it is not in the file).
    pub fn vehicle_type(&self, id: i32) -> String {
        self.types
            .get(&id)
            .cloned()
            .unwrap_or_else(|| "unknown_type".into())
    }

    /// The modem id of the vehicle `name` (ignoring case), or `name` read
    /// as a number.
    pub fn id(&self, name: &str) -> Option<i32> {
        self.names
            .iter()
            .find(|(_, n)| n.eq_ignore_ascii_case(name))
            .map(|(id, _)| *id)
            .or_else(|| name.trim().parse::<f64>().ok().map(|v| v as i32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn goby_lookup_files_read() {
        let lookup = ModemIdLookup::parse(
            "// modem id, vehicle name (should be community name), vehicle type, other aliases\n\
             0, broadcast, broadcast\n1, resolution, ship\n\n3, unicorn, auv # the AUV\n22, dee, kayak, dee-2\n",
        )
        .unwrap();
        assert_eq!(lookup.name(3), "unicorn");
        assert_eq!(lookup.name(7), "7");
        assert_eq!(lookup.vehicle_type(22), "kayak");
        assert_eq!(lookup.vehicle_type(7), "unknown_type");
        assert_eq!(lookup.id("UNICORN"), Some(3));
        assert_eq!(lookup.id("12"), Some(12));
        assert_eq!(lookup.id("nobody"), None);
        let err = ModemIdLookup::parse("1, a, b\n2, c\n").unwrap_err();
        assert!(err.starts_with("2: "), "{err}");
    }
}
