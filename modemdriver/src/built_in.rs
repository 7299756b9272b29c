//! The drivers built in: the one list of them ([`KINDS`]) and what reads
//! it — starting the driver a configuration names ([`start`]), finding
//! its kind ([`of`]), the names a configuration may give, Goby3's names of
//! the driver settings, driver-specific requests.
//!
//! What `gobyd --check` asks of a configuration without starting its
//! driver (its problems, its frame limits, its packet times) is in
//! [`crate::check`], which reads the same list.

use prost_reflect::{DynamicMessage, ReflectMessage};
use protos::goby::acomms::protobuf::{driver_config, DriverConfig, DriverType};

use crate::driver::{Driver, DriverError};
use crate::kind::DriverKind;
use crate::problem::Problem;

/// Every driver built in, in the order they are listed to users.
pub static KINDS: &[&dyn DriverKind] = &[
    &crate::udp::UdpDriver,
    &crate::udp_multicast::UdpMulticastDriver,
    &crate::sim::SimulatorDriver,
    &crate::micromodem::MicroModemDriver,
    &crate::evologics::EvologicsDriver,
    &crate::popoto::PopotoDriver,
    &crate::benthos::BenthosDriver,
    &crate::seatrac::SeatracDriver,
    &crate::iridium::IridiumDriver,
    #[cfg(feature = "iridium-shore")]
    &crate::iridium::IridiumShoreDriver,
];

/// The kind `config` names, or the problem of a configuration that names
/// none built in (its field `driver_type` or `driver_name`).
pub fn of(config: &DriverConfig) -> Result<&'static dyn DriverKind, Problem> {
    if let Some(kind) = KINDS.iter().find(|k| k.about().named.claims(config)) {
        return Ok(*kind);
    }
    Err(match &config.driver {
        Some(driver_config::Driver::DriverName(name)) => Problem::new(
            "driver_name",
            format!("no driver named {name:?} is built in ({})", named_ones()),
        ),
        Some(driver_config::Driver::DriverType(t)) => Problem::new(
            "driver_type",
            format!(
                "{} is not a driver built in (use {})",
                DriverType::try_from(*t)
                    .map(|t| t.as_str_name().to_string())
                    .unwrap_or_else(|_| format!("driver type {t}")),
                names()
            ),
        ),
        None => Problem::new(
            "driver_type",
            format!("DRIVER_NONE is not a driver built in (use {})", names()),
        ),
    })
}

/// The kind whose [`short_name`](crate::kind::About::short_name) is `name`.
pub fn by_short_name(name: &str) -> Option<&'static dyn DriverKind> {
    KINDS.iter().find(|k| k.about().short_name == name).copied()
}

/// Starts the driver `config` names.
///
/// # Errors
/// [`DriverError::Config`] for a configuration naming no driver built in
/// (`DriverConfig.driver_type: ...`) or one its driver refuses; what the
/// driver's start meets (a device that cannot be opened, a port taken).
pub async fn start(config: &DriverConfig) -> Result<Driver, DriverError> {
    let kind = of(config).map_err(Problem::into_error)?;
    kind.start(config).await
}

/// Every name a configuration may give, as it writes them, for messages:
/// `DRIVER_ACOUSTIC_SIMULATOR, DRIVER_UDP … or driver_name
/// "EVOLOGICS_S2C"`.
pub fn names() -> String {
    let names: Vec<String> = KINDS.iter().map(|k| k.about().named.written()).collect();
    match names.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
        None => String::new(),
    }
}

/// The drivers named by `driver_name`, for messages: `driver_name
/// "EVOLOGICS_S2C" is` (one), `driver_name "A" and "B" are`.
fn named_ones() -> String {
    let named: Vec<String> = KINDS
        .iter()
        .filter_map(|k| match k.about().named {
            crate::kind::Named::Name(name) => Some(format!("{name:?}")),
            crate::kind::Named::Type(_) => None,
        })
        .collect();
    match named.split_last() {
        None => "none is".to_string(),
        Some((last, [])) => format!("driver_name {last} is"),
        Some((last, rest)) => format!("driver_name {} and {last} are", rest.join(", ")),
    }
}

/// Goby3's extension names of driver settings, each with the field of
/// ours that holds the same settings (see
/// [`About::goby3_extensions`](crate::kind::About::goby3_extensions)).
pub fn goby3_extensions() -> impl Iterator<Item = (&'static str, &'static str)> {
    KINDS
        .iter()
        .flat_map(|k| k.about().goby3_extensions.iter().copied())
}

/// Whether the driver of `config` can carry out the driver-specific
/// request `message` from node `modem_id`, or why not: a driver that
/// takes none, a message of another type than the driver's, or what the
/// driver could not do with it.
pub fn specific_problem(
    config: &DriverConfig,
    message: &DynamicMessage,
    modem_id: i32,
) -> Result<(), String> {
    let name = message.descriptor().full_name().to_string();
    let kind = of(config).map_err(|p| format!("{name}: {}", p.reason))?;
    let Some(takes) = kind.specific() else {
        return Err(format!(
            "{name}: the {} driver takes no driver-specific requests",
            kind.about().named.name()
        ));
    };
    if message.descriptor() != takes {
        return Err(format!(
            "{name}: the {} driver takes {}",
            kind.about().title,
            takes.full_name()
        ));
    }
    match kind.specific_problem(config, message, modem_id) {
        Some(problem) => Err(problem),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each kind claims the configurations naming it and no other; no two
    /// kinds share a name, a short name or a section.
    #[test]
    fn every_kind_is_named_once() {
        for (i, a) in KINDS.iter().enumerate() {
            let config = match a.about().named {
                crate::kind::Named::Type(t) => DriverConfig {
                    driver: Some(driver_config::Driver::DriverType(t as i32)),
                    ..Default::default()
                },
                crate::kind::Named::Name(n) => DriverConfig {
                    driver: Some(driver_config::Driver::DriverName(n.into())),
                    ..Default::default()
                },
            };
            assert_eq!(
                of(&config).unwrap().about().short_name,
                a.about().short_name
            );
            for b in &KINDS[i + 1..] {
                assert_ne!(a.about().named, b.about().named);
                assert_ne!(a.about().short_name, b.about().short_name);
                assert!(a.about().section.is_none() || a.about().section != b.about().section);
            }
            assert_eq!(
                by_short_name(a.about().short_name).unwrap().about().named,
                a.about().named
            );
        }
    }

    #[test]
    fn a_configuration_naming_no_driver_built_in_is_told_the_names() {
        let typed = |t: DriverType| DriverConfig {
            driver: Some(driver_config::Driver::DriverType(t as i32)),
            ..Default::default()
        };
        let p = of(&typed(DriverType::DriverBluefinMoos)).err().unwrap();
        assert_eq!(p.field, "driver_type");
        assert!(
            p.reason
                .starts_with("DRIVER_BLUEFIN_MOOS is not a driver built in (use DRIVER_UDP, "),
            "{p}"
        );
        assert!(
            p.reason.contains(", driver_name \"EVOLOGICS_S2C\", "),
            "{p}"
        );
        assert!(p.reason.ends_with(" or DRIVER_IRIDIUM_SHORE)"), "{p}");
        let named = DriverConfig {
            driver: Some(driver_config::Driver::DriverName("EVOLOGICS_S3C".into())),
            ..Default::default()
        };
        let p = of(&named).err().unwrap().to_string();
        assert!(
            p.starts_with(
                "driver_name: no driver named \"EVOLOGICS_S3C\" is built in (driver_name "
            ),
            "{p}"
        );
        for kind in KINDS {
            if let crate::kind::Named::Name(name) = kind.about().named {
                assert!(p.contains(&format!("{name:?}")), "{p}");
            }
        }
        let named = KINDS
            .iter()
            .filter(|k| matches!(k.about().named, crate::kind::Named::Name(_)))
            .count();
        assert!(
            named_ones().ends_with(if named > 1 { " are" } else { " is" }),
            "{}",
            named_ones()
        );
        assert_eq!(
            of(&DriverConfig::default()).err().unwrap().field,
            "driver_type"
        );
    }

    #[test]
    fn goby3_extension_names_are_each_ones_own() {
        let mut names: Vec<&str> = goby3_extensions().map(|(n, _)| n).collect();
        let all = names.len();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), all);
        assert!(goby3_extensions().any(|e| e == ("goby.acomms.udp.protobuf.config", "udp")));
    }
}
