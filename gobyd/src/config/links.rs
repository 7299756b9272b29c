//! The links of a configuration: each a driver and its medium access
//! control, over the node's one queue and journal.
//!
//! A configuration gives either the top-level `driver` and `mac` (one
//! link, named [`DEFAULT_LINK`]) or `link { name driver mac cost budget
//! restart_min_seconds restart_max_seconds }` sections, one per link; and
//! `link_rule`s saying which links a type may use and how
//! ([`queue::links`]). [`links`] is the one view of either form: every
//! check of a driver or a MAC runs for each link it returns, on
//! [`LinkView::single`] (the configuration as if that link were its only
//! one), and names its fields with [`LinkView::field`]
//! (`link[1].driver.serial_port` in the link form, `driver.serial_port` in
//! the other).

use protos::goby::acomms::protobuf::{DriverConfig, MacConfig};
use protos::goby::apps::protobuf::gobyd_config::{self, LinkPolicy as ConfigPolicy};
use protos::goby::apps::protobuf::GobydConfig;
use queue::links::{LinkPolicy, LinkRule, LinkSpec, Links, MAX_LINKS};

use super::Problem;

/// The name of the one link of a configuration with a top-level `driver`.
pub const DEFAULT_LINK: &str = "default";

/// One link of a configuration.
#[derive(Debug, Clone)]
pub struct LinkView<'a> {
    /// Its place (0 first).
    pub index: usize,
    /// Its name.
    pub name: String,
    /// Its driver section (`None`: not given; a [completed](super::complete)
    /// configuration has one).
    pub driver: Option<&'a DriverConfig>,
    /// Its MAC section (`None`: not given; completed, it has one).
    pub mac: Option<&'a MacConfig>,
    /// Its `link` section (`None`: the top-level form).
    pub section: Option<&'a gobyd_config::Link>,
}

impl LinkView<'_> {
    /// The frame each TDMA slot of node `me` on this link offers, bytes, in
    /// the MAC's order: as its driver offers it
    /// ([`modemdriver::check::frame_in_slot`]), or a Micro-Modem's frame of
    /// the slot's rate when the link names no driver; `None` for a slot
    /// whose frame is not known. Empty without a MAC or a slot of `me`'s.
    pub fn own_slot_frames(&self, me: i32) -> Vec<Option<usize>> {
        let Some(mac) = self.mac else {
            return Vec::new();
        };
        mac.slot
            .iter()
            .filter(|s| s.src.is_none_or(|src| src == me))
            .map(|slot| match self.driver {
                Some(driver) => modemdriver::check::frame_in_slot(driver, slot),
                None => modemdriver::rate::spec(slot.rate()).map(|s| s.frame_bytes as usize),
            })
            .collect()
    }

    /// The path of `field` of the link (`driver.udp.local.port`,
    /// `mac.slot[0]`, `budget.bytes`) from the top of the configuration.
    pub fn field(&self, field: &str) -> String {
        match self.section {
            Some(_) => format!("link[{}].{field}", self.index),
            None => field.to_string(),
        }
    }

    /// `config` as if this link were its only one: its driver and MAC at
    /// the top, no `link` sections (for the checks written for one).
    pub fn single(&self, config: &GobydConfig) -> GobydConfig {
        GobydConfig {
            driver: self.driver.cloned(),
            mac: self.mac.cloned(),
            link: Vec::new(),
            ..config.clone()
        }
    }

    /// What a message over it costs (1 unless given).
    pub fn cost(&self) -> f64 {
        self.section.map_or(1.0, |l| l.cost())
    }

    /// Its byte budget: bytes per period and the period in seconds.
    pub fn budget(&self) -> Option<(u64, f64)> {
        let b = self.section?.budget.as_ref()?;
        Some((b.bytes(), b.period_seconds()))
    }

    /// The first and the longest wait before its driver is started again
    /// after a failure, seconds.
    pub fn restart(&self) -> (f64, f64) {
        self.section.map_or((1.0, 60.0), |l| {
            (l.restart_min_seconds(), l.restart_max_seconds())
        })
    }

    /// The largest frame its driver sends, bytes, when it has a limit of
    /// its own (the EvoLogics S2C's burst, Iridium SBD's messages).
    pub fn largest_frame(&self) -> Option<usize> {
        let driver = self.driver?;
        modemdriver::check::largest_frame(driver)
            .or_else(|| modemdriver::check::frame_limits(driver).map(|l| l.outgoing))
    }
}

/// The links of `config`, in order: its `link` sections, or the one link
/// of its top-level `driver` and `mac` (named [`DEFAULT_LINK`]).
pub fn links(config: &GobydConfig) -> Vec<LinkView<'_>> {
    if config.link.is_empty() {
        return vec![LinkView {
            index: 0,
            name: DEFAULT_LINK.to_string(),
            driver: config.driver.as_ref(),
            mac: config.mac.as_ref(),
            section: None,
        }];
    }
    config
        .link
        .iter()
        .enumerate()
        .map(|(index, l)| LinkView {
            index,
            name: l.name().to_string(),
            driver: l.driver.as_ref(),
            mac: l.mac.as_ref(),
            section: Some(l),
        })
        .collect()
}

/// Whether `config` is written with `link` sections (each link then runs
/// under the link supervisor: restarts, budgets, rules).
pub fn has_link_sections(config: &GobydConfig) -> bool {
    !config.link.is_empty()
}

/// `problems` of `view.single(..)`, their fields named within the link
/// (`driver.…` and `mac.…` become `link[i].driver.…`).
pub fn within(view: &LinkView<'_>, problems: Vec<Problem>) -> Vec<Problem> {
    problems
        .into_iter()
        .map(|mut p| {
            if p.field.starts_with("driver") || p.field.starts_with("mac") {
                p.field = view.field(&p.field);
            }
            p
        })
        .collect()
}

/// Why a link name cannot be used, if it cannot.
fn name_problem(name: &str) -> Option<String> {
    if name.is_empty() {
        return Some("missing: give each link a name (e.g. \"acoustic\", \"iridium\")".into());
    }
    if !name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        return Some(format!(
            "{name:?}: a link's name is letters, digits, '_' and '-' (it is an MQTT topic level and a MOOS value)"
        ));
    }
    None
}

/// The problems of the `link` sections themselves (the drivers and MACs
/// are checked as for one link): both forms at once, names missing,
/// repeated or unusable, too many links, a cost, budget or restart time
/// that is not a number of its kind.
pub fn link_problems(config: &GobydConfig) -> Vec<Problem> {
    let mut problems = Vec::new();
    if config.link.is_empty() {
        return problems;
    }
    if config.link.len() > MAX_LINKS {
        problems.push(Problem::new(
            format!("link[{MAX_LINKS}]"),
            format!(
                "{} links: gobyd runs at most {MAX_LINKS}",
                config.link.len()
            ),
        ));
    }
    for (i, link) in config.link.iter().enumerate() {
        let field = |f: &str| format!("link[{i}].{f}");
        if let Some(reason) = name_problem(link.name()) {
            problems.push(Problem::new(field("name"), reason));
        } else if let Some(first) = config.link[..i].iter().position(|l| l.name == link.name) {
            problems.push(Problem::new(
                field("name"),
                format!(
                    "{:?} is the name of link[{first}] too: each link has its own",
                    link.name()
                ),
            ));
        }
        if link.driver.is_none() {
            problems.push(Problem::new(
                field("driver"),
                "missing: each link has its driver (driver { driver_type: ... })",
            ));
        }
        if !(link.cost().is_finite() && link.cost() >= 0.0) {
            problems.push(Problem::new(
                field("cost"),
                format!("{} is not a cost (0 or more)", link.cost()),
            ));
        }
        if let Some(budget) = &link.budget {
            match budget.bytes {
                None => problems.push(Problem::new(
                    field("budget.bytes"),
                    "missing: give the bytes the link may send per period",
                )),
                Some(0) => problems.push(Problem::new(
                    field("budget.bytes"),
                    "0: the link could never send (give it the bytes it may send per period, or \
                     leave it out of the link rules)",
                )),
                Some(_) => {}
            }
            let period = budget.period_seconds();
            if !(period.is_finite() && period >= 1.0) {
                problems.push(Problem::new(
                    field("budget.period_seconds"),
                    format!("{period} is not a period (1 s or more)"),
                ));
            }
        }
        let device_of = |l: &gobyd_config::Link| l.driver.as_ref().and_then(device);
        if let Some((at, what)) = device_of(link) {
            let before = config.link[..i]
                .iter()
                .position(|l| device_of(l).is_some_and(|(_, w)| w == what));
            if let Some(first) = before {
                problems.push(Problem::new(
                    field(&format!("driver.{at}")),
                    format!(
                        "{what} is link[{first}]'s too: two drivers cannot hold one device \
                         (give each link its own)"
                    ),
                ));
            }
        }
        let (min, max) = (link.restart_min_seconds(), link.restart_max_seconds());
        if !(min.is_finite() && min > 0.0) {
            problems.push(Problem::new(
                field("restart_min_seconds"),
                format!("{min} is not a wait in seconds (more than 0)"),
            ));
        } else if !(max.is_finite() && max >= min) {
            problems.push(Problem::new(
                field("restart_max_seconds"),
                format!("{max} is less than restart_min_seconds ({min})"),
            ));
        }
    }
    problems
}

/// The device a link's driver holds for itself, as `(field, words)`: a
/// UDP driver's local port, a serial line. Two links may not hold one
/// (the second would never start); a TCP client's server may serve
/// several.
fn device(driver: &DriverConfig) -> Option<(&'static str, String)> {
    use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver};
    use protos::goby::acomms::protobuf::DriverType;
    let kind = match &driver.driver {
        Some(Driver::DriverType(t)) => DriverType::try_from(*t).ok(),
        _ => None,
    };
    match kind {
        Some(DriverType::DriverUdp) => {
            let port = driver.udp.as_ref()?.local.port;
            (port != 0).then(|| ("udp.local.port", format!("UDP port {port}")))
        }
        Some(DriverType::DriverUdpMulticast | DriverType::DriverAcousticSimulator) | None => None,
        Some(_) => {
            let serial = driver.connection_type() == ConnectionType::ConnectionSerial;
            let port = driver.serial_port().trim();
            (serial && !port.is_empty()).then(|| ("serial_port", format!("serial port {port:?}")))
        }
    }
}

/// The problems of the `link_rule`s, against the links of `config` and
/// the DCCL types `loaded`: a type that is not loaded, a link that does
/// not exist or is named twice, no link, a timeout that is not a time, two
/// rules for one type (or two without a type).
pub fn rule_problems(config: &GobydConfig, loaded: &[String]) -> Vec<Problem> {
    let mut problems = Vec::new();
    let views = links(config);
    let names: Vec<&str> = views.iter().map(|v| v.name.as_str()).collect();
    for (i, rule) in config.link_rule.iter().enumerate() {
        let field = |f: &str| format!("link_rule[{i}].{f}");
        match &rule.protobuf_name {
            Some(name) if !loaded.contains(name) => problems.push(Problem::new(
                field("protobuf_name"),
                format!(
                    "{name:?} is not a DCCL type of the loaded .proto files (loaded: {})",
                    if loaded.is_empty() {
                        "none".to_string()
                    } else {
                        loaded.join(", ")
                    }
                ),
            )),
            _ => {}
        }
        if let Some(first) = config.link_rule[..i]
            .iter()
            .position(|r| r.protobuf_name == rule.protobuf_name)
        {
            problems.push(Problem::new(
                if rule.protobuf_name.is_some() {
                    field("protobuf_name")
                } else {
                    format!("link_rule[{i}]")
                },
                match &rule.protobuf_name {
                    Some(name) => {
                        format!("a second rule for {name} (link_rule[{first}] is one): give one")
                    }
                    None => format!(
                        "a second rule without protobuf_name (link_rule[{first}] is the default rule already): give one"
                    ),
                },
            ));
        }
        if rule.link.is_empty() {
            problems.push(Problem::new(
                format!("link_rule[{i}]"),
                format!("names no link: give one or more (link: \"{}\")", names[0]),
            ));
        }
        for (j, link) in rule.link.iter().enumerate() {
            let field = field(&format!("link[{j}]"));
            if !names.contains(&link.as_str()) {
                problems.push(Problem::new(
                    field,
                    format!(
                        "{link:?} is not a link of this node (links: {})",
                        names.join(", ")
                    ),
                ));
            } else if rule.link[..j].contains(link) {
                problems.push(Problem::new(field, format!("{link:?} is named twice")));
            }
        }
        let timeout = rule.timeout_seconds();
        if !(timeout.is_finite() && timeout >= 0.0) {
            problems.push(Problem::new(
                field("timeout_seconds"),
                format!("{timeout} is not a time in seconds (0 or more)"),
            ));
        }
    }
    problems
}

fn policy(p: ConfigPolicy) -> LinkPolicy {
    match p {
        ConfigPolicy::PriorityTimeout => LinkPolicy::PriorityTimeout,
        ConfigPolicy::FloodAll => LinkPolicy::FloodAll,
        ConfigPolicy::CheapestFirst => LinkPolicy::CheapestFirst,
    }
}

/// The links and rules of a checked configuration as the queue takes them
/// (`None` in the top-level form: one link, no rules). `id_of` gives a
/// type's DCCL id.
pub fn queue_links(
    config: &GobydConfig,
    id_of: impl Fn(&str) -> Option<u32>,
) -> Result<Option<Links>, String> {
    if !has_link_sections(config) {
        return Ok(None);
    }
    let views = links(config);
    let specs = views
        .iter()
        .map(|v| LinkSpec {
            name: v.name.clone(),
            cost: v.cost(),
            largest_frame: v.largest_frame(),
        })
        .collect();
    let mut links = Links::new(specs).map_err(|e| e.to_string())?;
    for (i, rule) in config.link_rule.iter().enumerate() {
        let indices = rule
            .link
            .iter()
            .map(|name| {
                views
                    .iter()
                    .position(|v| &v.name == name)
                    .ok_or_else(|| format!("link_rule[{i}]: no link {name:?}"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let rule_of = LinkRule::new(indices, policy(rule.policy()), rule.timeout_seconds());
        let set = match &rule.protobuf_name {
            None => links.set_default_rule(rule_of),
            Some(name) => {
                let id =
                    id_of(name).ok_or_else(|| format!("link_rule[{i}]: no DCCL type {name}"))?;
                links.set_rule(id, rule_of)
            }
        };
        set.map_err(|e| format!("link_rule[{i}]: {e}"))?;
    }
    Ok(Some(links))
}

/// The links and rules of a configuration with `link` sections in words,
/// for `gobyd --check`: `links: acoustic (cost 1), iridium (cost 10, budget
/// 2000 bytes per 86400 s); goby.example.Command: acoustic, then iridium
/// after 120 s`.
pub fn summary(config: &GobydConfig) -> String {
    let links_text: Vec<String> = links(config)
        .iter()
        .map(|v| match v.budget() {
            Some((bytes, period)) => {
                format!(
                    "{} (cost {}, budget {bytes} bytes per {period} s)",
                    v.name,
                    v.cost()
                )
            }
            None => format!("{} (cost {})", v.name, v.cost()),
        })
        .collect();
    let mut text = format!("links: {}", links_text.join(", "));
    for rule in &config.link_rule {
        let who = rule
            .protobuf_name
            .as_deref()
            .unwrap_or("types without a rule");
        let how = match rule.policy() {
            ConfigPolicy::FloodAll => format!("all at once over {}", rule.link.join(", ")),
            policy => {
                let mut order = rule.link.clone();
                if policy == ConfigPolicy::CheapestFirst {
                    let views = links(config);
                    let cost = |n: &String| {
                        views
                            .iter()
                            .find(|v| &v.name == n)
                            .map_or(0.0, |v| v.cost())
                    };
                    order.sort_by(|a, b| cost(a).total_cmp(&cost(b)));
                }
                let mut how = order.first().cloned().unwrap_or_default();
                for next in order.iter().skip(1) {
                    how.push_str(&format!(", then {next} after {} s", rule.timeout_seconds()));
                }
                how
            }
        };
        text.push_str(&format!("; {who}: {how}"));
    }
    text
}
