//! The MAC switcher's section (`mac_switcher`): named medium access
//! configurations for the first link, one of them the default
//! (`default_mac`), switched between at sea (the daemon's side is
//! the core's `mac_switcher` module).
//!
//! Completing a configuration puts the default's MAC where the first
//! link's `mac` goes (`mac`, or `link[0].mac`), so that every check of a
//! link's MAC checks it; the other MACs are checked the same way, their
//! problems named `mac_switcher.mac[I].mac.…`. Refused, naming the place:
//! a `default_mac` that names none of them, a name missing, unusable or
//! given twice, the first link's `mac` given beside the switcher.

use amac::MacManager;
use protos::goby::apps::protobuf::GobydConfig;
use queue::{Clock, SystemClock};

use super::{links, DriverSettings, Problem};

/// Fills in the first link's `mac` with the switcher's default (each
/// named MAC given the modem id `id` where unset). Errors: what is
/// refused, each named by its field.
pub fn complete(config: &mut GobydConfig, id: i32) -> Result<(), Vec<Problem>> {
    let Some(switcher) = config.mac_switcher.as_mut() else {
        return Ok(());
    };
    let mut problems = name_problems(switcher);
    let first_mac = match config.link.first_mut() {
        Some(link) => (&mut link.mac, "link[0].mac"),
        None => (&mut config.mac, "mac"),
    };
    if first_mac.0.is_some() {
        problems.push(Problem::new(
            first_mac.1,
            "given beside mac_switcher: the first link's MAC is the switcher's default_mac; \
             move it into mac_switcher { mac { name: \"...\" mac { ... } } }",
        ));
    }
    for (i, named) in switcher.mac.iter_mut().enumerate() {
        let mac = named.mac.get_or_insert_with(|| super::default_mac(id));
        if let Err(super::ConfigError::Problems(p)) = super::same_id(
            &format!("mac_switcher.mac[{i}].mac.modem_id"),
            mac.modem_id,
            id,
        ) {
            problems.extend(p);
        }
        mac.modem_id.get_or_insert(id);
    }
    if !problems.is_empty() {
        return Err(problems);
    }
    let default = switcher
        .mac
        .iter()
        .find(|m| m.name() == switcher.default_mac())
        .and_then(|m| m.mac.clone());
    *first_mac.0 = default;
    Ok(())
}

/// The problems of the names: `default_mac` naming none, a name missing,
/// unusable or given twice.
fn name_problems(switcher: &protos::goby::acomms::protobuf::MacSwitcherConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    let names: Vec<&str> = switcher.mac.iter().map(|m| m.name()).collect();
    for (i, name) in names.iter().enumerate() {
        let field = format!("mac_switcher.mac[{i}].name");
        if name.is_empty() {
            problems.push(Problem::new(field, "missing: give each MAC a name"));
        } else if !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            problems.push(Problem::new(
                field,
                format!("{name:?}: a MAC's name is letters, digits, '_' and '-'"),
            ));
        } else if let Some(j) = names[..i].iter().position(|n| n == name) {
            problems.push(Problem::new(
                field,
                format!("{name:?} is also mac_switcher.mac[{j}].name: names must differ"),
            ));
        }
    }
    let default = switcher.default_mac();
    if !names.contains(&default) {
        problems.push(Problem::new(
            "mac_switcher.default_mac",
            format!(
                "{default:?} names no MAC of mac_switcher (its MACs: {}); \
                 give the name of the MAC to run at start and to go back to",
                if names.is_empty() {
                    "none".to_string()
                } else {
                    names.join(", ")
                }
            ),
        ));
    }
    problems
}

/// The problems of the switcher's MACs other than the default (which is
/// checked as the first link's MAC): each checked as the first link's MAC
/// would be (its own slot, its slots against the driver, what the MAC
/// itself refuses), named `mac_switcher.mac[I].mac.…`.
pub fn problems(config: &GobydConfig, driver: DriverSettings) -> Vec<Problem> {
    let Some(switcher) = &config.mac_switcher else {
        return Vec::new();
    };
    let Some(first) = links::links(config).into_iter().next() else {
        return Vec::new();
    };
    let mut problems = Vec::new();
    for (i, named) in switcher.mac.iter().enumerate() {
        if named.name() == switcher.default_mac() {
            continue;
        }
        let Some(mac) = &named.mac else {
            continue;
        };
        let single = GobydConfig {
            mac: Some(mac.clone()),
            ..first.single(config)
        };
        let mut found = Vec::new();
        if let Some((field, reason)) = super::own_slot_problem(&single) {
            found.push(Problem::new(field, reason));
        }
        if driver == DriverSettings::Configured {
            found.extend(super::driver_problems(&single));
        }
        if let Err(amac::AmacError::InvalidField { field, reason, .. }) =
            MacManager::new(mac, SystemClock.now())
        {
            found.push(Problem::new(format!("mac.{field}"), reason));
        }
        problems.extend(
            found
                .into_iter()
                .filter(|p| p.field.starts_with("mac"))
                .map(|p| Problem::new(format!("mac_switcher.mac[{i}].{}", p.field), p.reason)),
        );
    }
    problems.dedup_by(|a, b| a.field == b.field);
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(text: &str) -> Vec<Problem> {
        let config = super::super::parse(text, "switcher.cfg").unwrap();
        match super::super::complete(config) {
            Err(super::super::ConfigError::Problems(p)) => p,
            Ok(config) => problems(&config, DriverSettings::Configured),
            Err(e) => panic!("{e}"),
        }
    }

    const TWO: &str = "mac { name: \"survey\" mac { slot { src: 1 slot_seconds: 10 } } }
                       mac { name: \"quiet\" mac { slot { src: 2 slot_seconds: 10 } slot { src: 1 slot_seconds: 30 } } }";

    #[test]
    fn the_default_runs_as_the_first_links_mac() {
        let text = format!("mac_switcher {{ default_mac: \"quiet\" {TWO} }}");
        let config = super::super::complete(super::super::parse(&text, "s.cfg").unwrap()).unwrap();
        let mac = config.mac.clone().unwrap();
        assert_eq!(mac.slot.len(), 2);
        assert_eq!(mac.modem_id, Some(1));
        assert!(problems(&config, DriverSettings::Configured).is_empty());
    }

    #[test]
    fn a_missing_default_clashing_names_and_a_mac_beside_are_refused_naming_the_place() {
        let p = refused(&format!("mac_switcher {{ default_mac: \"loud\" {TWO} }}"));
        assert_eq!(p[0].field, "mac_switcher.default_mac");
        assert!(p[0].reason.contains("survey, quiet"), "{}", p[0].reason);
        let p =
            refused("mac_switcher { default_mac: \"a\" mac { name: \"a\" } mac { name: \"a\" } }");
        assert_eq!(p[0].field, "mac_switcher.mac[1].name");
        assert!(p[0].reason.contains("mac_switcher.mac[0].name"));
        let p = refused(&format!(
            "mac {{ slot {{ src: 1 }} }} mac_switcher {{ default_mac: \"quiet\" {TWO} }}"
        ));
        assert_eq!(p[0].field, "mac");
    }

    #[test]
    fn another_macs_own_problems_are_named_within_the_switcher() {
        let p = refused(
            "driver { driver_type: DRIVER_ACOUSTIC_SIMULATOR } \
             mac_switcher { default_mac: \"a\" mac { name: \"a\" } \
             mac { name: \"b\" mac { type: MAC_FIXED_DECENTRALIZED slot { src: 2 slot_seconds: 10 } } } \
             mac { name: \"c\" mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 slot_seconds: 0.1 } } } }",
        );
        let fields: Vec<&str> = p.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(
            fields,
            [
                "mac_switcher.mac[1].mac.slot",
                "mac_switcher.mac[2].mac.slot[0].slot_seconds"
            ],
            "{p:?}"
        );
    }
}
