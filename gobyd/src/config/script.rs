//! Scripted TDMA (as WHOI's ros_acomms has it): a slot of a cycle may
//! name the DCCL types it carries (`packet_type`, full names, or "any"),
//! each slot at its own `rate`; when this node initiates the slot the
//! queue is asked for those types alone.
//!
//! Refused, naming the place: a type that is not loaded, and a type whose
//! largest encoding does not fit one frame of the slot, as its driver
//! offers it (a Micro-Modem's frame of the slot's rate, a SeaTrac's frame
//! limit): it could never go in that slot. A slot too short for its rate's packet
//! is refused as every slot is (`mac.slot[I].slot_seconds`).

use protos::goby::acomms::protobuf::MacConfig;
use protos::goby::apps::protobuf::GobydConfig;

use super::{links, Problem};

/// The problems of every scripted slot of `config` (each link's MAC and
/// the MAC switcher's); `max_size`: a loaded type's largest encoding in
/// bytes (`None`: not loaded).
pub fn problems(config: &GobydConfig, max_size: impl Fn(&str) -> Option<usize>) -> Vec<Problem> {
    let mut problems = Vec::new();
    let views = links::links(config);
    for view in &views {
        if let Some(mac) = view.mac {
            let place = view.field("mac");
            problems.extend(mac_problems(mac, &place, view.driver, &max_size));
        }
    }
    let first_driver = views.first().and_then(|v| v.driver);
    for (k, named) in config
        .mac_switcher
        .iter()
        .flat_map(|s| s.mac.iter().enumerate())
    {
        if let Some(mac) = &named.mac {
            let place = format!("mac_switcher.mac[{k}].mac");
            problems.extend(mac_problems(mac, &place, first_driver, &max_size));
        }
    }
    problems.dedup_by(|a, b| a.field == b.field && a.reason == b.reason);
    problems
}

/// The problems of the scripted slots of `mac` (named from `place`).
fn mac_problems(
    mac: &MacConfig,
    place: &str,
    driver: Option<&protos::goby::acomms::protobuf::DriverConfig>,
    max_size: &impl Fn(&str) -> Option<usize>,
) -> Vec<Problem> {
    let mut problems = Vec::new();
    for (i, slot) in mac.slot.iter().enumerate() {
        let frame = driver.and_then(|d| modemdriver::check::frame_in_slot(d, slot));
        for (j, name) in slot.packet_type.iter().enumerate() {
            let field = format!("{place}.slot[{i}].packet_type[{j}]");
            if name == "any" {
                continue;
            }
            let Some(size) = max_size(name) else {
                problems.push(Problem::new(
                    field,
                    format!("{name:?} is not a loaded DCCL type (give a full name, e.g. goby.example.Command, or \"any\")"),
                ));
                continue;
            };
            if let Some(frame) = frame.filter(|&f| size > f) {
                problems.push(Problem::new(
                    field,
                    format!(
                        "{name} encodes to up to {size} bytes, more than the {frame}-byte frame of this \
                         slot (rate {}): it could never go in this slot (give it a rate or a link with \
                         larger frames)",
                        slot.rate()
                    ),
                ));
            }
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    fn problems_of(text: &str) -> Vec<Problem> {
        let config =
            super::super::complete(super::super::parse(text, "script.cfg").unwrap()).unwrap();
        problems(&config, |name| match name {
            "goby.example.Small" => Some(20),
            "goby.example.Large" => Some(200),
            _ => None,
        })
    }

    #[test]
    fn unknown_types_and_types_larger_than_the_rates_frame_are_refused_naming_the_place() {
        let p = problems_of(
            "mac { type: MAC_FIXED_DECENTRALIZED \
             slot { src: 1 rate: 0 slot_seconds: 20 packet_type: \"goby.example.Small\" packet_type: \"goby.example.Large\" } \
             slot { src: 1 rate: 5 slot_seconds: 20 packet_type: \"goby.example.Large\" packet_type: \"any\" packet_type: \"Nope\" } }",
        );
        let fields: Vec<&str> = p.iter().map(|p| p.field.as_str()).collect();
        assert_eq!(
            fields,
            ["mac.slot[0].packet_type[1]", "mac.slot[1].packet_type[2]"],
            "{p:?}"
        );
        assert!(
            p[0].reason.contains("32-byte frame of this slot (rate 0)"),
            "{}",
            p[0].reason
        );
        assert!(p[1].reason.contains("\"Nope\""), "{}", p[1].reason);
    }

    #[test]
    fn the_switchers_macs_are_checked_too() {
        let p = problems_of(
            "mac_switcher { default_mac: \"a\" mac { name: \"a\" } \
             mac { name: \"b\" mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 packet_type: \"Nope\" } } } }",
        );
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!(p[0].field, "mac_switcher.mac[1].mac.slot[0].packet_type[0]");
    }
}
