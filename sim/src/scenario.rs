//! The scenario: `goby.sim.protobuf.Scenario` read from protobuf text
//! format and checked before anything runs.
//!
//! Every mistake is refused at once, each naming where it is written
//! (`FILE:LINE:COLUMN: node[1].traffic[0].dest: no node named "auv3"`) or,
//! for what is not written, its path: an unknown destination node, a name
//! or modem id used twice, a node's gobyd configuration that gobyd's own
//! checks refuse (those `gobyd --check` runs, with the simulator's driver
//! in place of the configuration's), a type the node's gobyd does not load,
//! a field value its type cannot take, a period or rate that is not
//! positive, a duration that is not positive, a fault naming an unknown
//! node or out of the run ([`crate::fault`]).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use gobyd::config::{ConfigError, Problem};
use gobyd::error::DaemonError;
use prost_reflect::{DynamicMessage, MessageDescriptor, ReflectMessage};
use protos::goby::acomms::protobuf::queued_message_entry::{role::RoleSetting, RoleType};
use protos::goby::acomms::protobuf::{DriverConfig, SatelliteLink, SimulatorDriverConfig};
use protos::goby::apps::protobuf::GobydConfig;
use protos::goby::sim::protobuf as pb;

use crate::track::{Place, Track};
use crate::traffic::{Rate, Stream, ValueGen};

/// A scenario that passed every check, ready to run ([`crate::run`]).
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Seed of every random draw of the run.
    pub seed: u64,
    /// Virtual time of the start, microseconds since the UNIX epoch.
    pub start_micros: i64,
    /// Microseconds of traffic.
    pub duration_micros: u64,
    /// Microseconds after the traffic in which what is owed may still go.
    pub drain_micros: u64,
    /// The water of every node's simulated modem (positions, seed,
    /// channel and UDP endpoints left unset: the run sets them).
    pub water: SimulatorDriverConfig,
    /// The satellite link of the nodes with an Iridium driver.
    pub satellite: SatelliteLink,
    /// The nodes, in the order written.
    pub nodes: Vec<Node>,
    /// What goes wrong, and when.
    pub faults: Vec<crate::fault::Fault>,
    /// File names of the report (relative to the output directory).
    pub report: pb::Report,
}

/// One node of a [`Scenario`].
#[derive(Debug, Clone)]
pub struct Node {
    /// Its unique name.
    pub name: String,
    /// Its unique modem id.
    pub modem_id: i32,
    /// Its gobyd configuration, with the modem id set and the interfaces
    /// off (the run sets the driver and the data directory).
    pub config: GobydConfig,
    /// The DCCL types its gobyd loads.
    pub codec: Arc<dccl::Codec>,
    /// Where it is over the run: fixed, or on its track.
    pub place: Place,
    /// What its autonomy publishes.
    pub traffic: Vec<Stream>,
    /// Its simulated modem in words: the modem it sends as
    /// (`"DRIVER_POPOTO"`), or the simulator's own rates and why (empty
    /// for a node on the satellite alone).
    pub modem: String,
    /// Where each of its links goes, in the order of its `link` sections
    /// (the one link of a top-level `driver`).
    pub links: Vec<Medium>,
    /// The name of its link on the satellite, with `link` sections.
    pub satellite_link: Option<String>,
}

/// Where a node's link goes: the water, or the satellite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Medium {
    /// The scenario's water, its simulated modem sending as the node's.
    Water,
    /// The satellite (an Iridium driver), [`Scenario::satellite`].
    Satellite,
}

/// Where a node's links go, as the check found them.
#[derive(Debug, Clone, Default)]
struct NodeLinks {
    /// Each link's medium, in order.
    media: Vec<Medium>,
    /// The name of its link on the satellite, with `link` sections.
    satellite_link: Option<String>,
    /// Its link on the satellite in words.
    satellite_words: Option<String>,
}

/// A scenario refused: every problem found, one a line.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{}", .0.join("\n"))]
pub struct ScenarioError(pub Vec<String>);

/// Reads and checks the scenario in the file `path` (a node's
/// `gobyd_file` is read relative to its directory).
pub fn load(path: &Path) -> Result<Scenario, ScenarioError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| ScenarioError(vec![format!("cannot read {}: {e}", path.display())]))?;
    parse(&text, &path.display().to_string(), &base_of(path))
}

/// Checks the scenario `text`; `origin` names it in errors, `base` is the
/// directory a node's `gobyd_file` is read relative to.
pub fn parse(text: &str, origin: &str, base: &Path) -> Result<Scenario, ScenarioError> {
    let desc = pb::Scenario::default().descriptor();
    let parsed = DynamicMessage::parse_text_format(desc, text)
        .map_err(|e| ScenarioError(vec![parse_error(&e, text, origin)]))?
        .transcode_to::<pb::Scenario>()
        .map_err(|e| ScenarioError(vec![format!("{origin}: {e}")]))?;
    let mut check = Check {
        text,
        origin,
        base,
        found: Vec::new(),
        start_s: None,
        duration_s: 0.0,
        water: SimulatorDriverConfig::default(),
        water_refused: Vec::new(),
        modems: Default::default(),
        satellite: SatelliteLink::default(),
        links: Default::default(),
    };
    let scenario = check.scenario(parsed);
    match check.found.is_empty() {
        true => Ok(scenario.expect("complete when nothing was found")),
        false => Err(ScenarioError(check.found)),
    }
}

/// The parser's error at its line and column.
fn parse_error(e: &prost_reflect::text_format::ParseError, text: &str, origin: &str) -> String {
    use miette::Diagnostic;
    match e.labels().and_then(|mut l| l.next()).map(|l| l.offset()) {
        Some(offset) => {
            let (line, column) = gobyd::config::line_and_column(text, offset);
            format!("{origin}:{line}:{column}: {e}")
        }
        None => format!("{origin}: {e}"),
    }
}

/// The checks, collecting every problem with its place.
pub(crate) struct Check<'a> {
    text: &'a str,
    origin: &'a str,
    base: &'a Path,
    found: Vec<String>,
    /// The virtual start, seconds since the UNIX epoch (`None`: refused).
    start_s: Option<i64>,
    /// The seconds of traffic (`duration_s`), for the streams' sizes.
    duration_s: f64,
    /// The simulated water, which each node's driver is checked with.
    water: SimulatorDriverConfig,
    /// The fields of each node's driver the water's problems are told
    /// at (`driver.simulator.…`): told once, as `water.…`.
    water_refused: Vec<String>,
    /// Each node's simulated modem ([`crate::modem::sends_as`]), by node
    /// index: the modem its configuration names (`None`: none, or the
    /// simulator without one), and in words (nodes on the water only).
    modems: std::collections::BTreeMap<usize, (Option<String>, String)>,
    /// The satellite link of the Iridium drivers.
    satellite: SatelliteLink,
    /// Each node's links' media, the name of its satellite link and that
    /// link in words, by node index.
    links: std::collections::BTreeMap<usize, NodeLinks>,
}

/// The longest `duration_s` or `drain_s` a run takes: a year.
const MAX_SECONDS: f64 = 366.0 * 86_400.0;

/// The farthest a node may be from the scenario's origin, east or north,
/// metres: 10 000 km.
const MAX_OFFSET: f64 = 1e7;

/// The deepest a node may be, metres (the Challenger Deep is under 11 km).
const MAX_DEPTH: f64 = 11_000.0;

/// The fastest a node may go on its track, metres per second: faster than
/// any vehicle or ship at sea.
const MAX_SPEED: f64 = 30.0;

/// The most publications one stream may make in a run (about, for a
/// Poisson stream): more is a mistake in its rate or the duration, and
/// would hold the run for hours.
const MAX_PUBLICATIONS: f64 = 1_000_000.0;

fn too_long(seconds: f64) -> String {
    format!(
        "{seconds} s is more than a year ({MAX_SECONDS} s): a run is a mission's length or a few"
    )
}

impl Check<'_> {
    /// A problem of the scenario's field `path`, placed where it is written.
    pub(crate) fn problem(&mut self, path: impl Into<String>, reason: impl Into<String>) {
        let mut problems = [Problem::new(path, reason)];
        gobyd::config::locate(&mut problems, self.text, self.origin);
        let [p] = problems;
        self.found.push(match p.place {
            Some(place) => format!("{place}: {}: {}", p.field, p.reason),
            None => format!("{}: {}: {}", self.origin, p.field, p.reason),
        });
    }

    fn scenario(&mut self, s: pb::Scenario) -> Option<Scenario> {
        let duration = s.duration_s.unwrap_or(0.0);
        if !(duration > 0.0 && duration.is_finite()) {
            self.problem("duration_s", "give the seconds of traffic, more than 0");
        } else if duration > MAX_SECONDS {
            self.problem("duration_s", too_long(duration));
        }
        let drain = s.drain_s();
        if !(drain >= 0.0 && drain.is_finite()) {
            self.problem("drain_s", format!("{drain} is not 0 or more seconds"));
        } else if drain > MAX_SECONDS {
            self.problem("drain_s", too_long(drain));
        }
        // A duration or a start refused above is not checked against again
        // (no follow-on problems of the streams).
        self.duration_s = if duration > 0.0 && duration <= MAX_SECONDS {
            duration
        } else {
            0.0
        };
        let start = start_micros(s.start_time());
        match &start {
            Ok(micros) => self.start_s = Some(micros.div_euclid(1_000_000)),
            Err(e) => self.problem("start_time", e.clone()),
        }
        let water = s.water.clone().unwrap_or_default();
        self.water(&water);
        self.water = water.clone();
        let satellite = s.satellite.unwrap_or_default();
        self.satellite(&satellite);
        self.satellite = satellite;
        self.report(&s.report.clone().unwrap_or_default());
        if s.node.is_empty() {
            self.problem("node", "a scenario needs at least one node");
        }
        self.names_and_ids(&s.node);
        let mut nodes = Vec::new();
        for (i, node) in s.node.iter().enumerate() {
            nodes.push(self.node(i, node, &s.node));
        }
        let nodes: Option<Vec<Node>> = nodes.into_iter().collect();
        self.one_modem_on_the_water();
        // Settings that apply to no node are a mistake, not a default
        // (told once every node's links are known, whatever else is wrong).
        let every_node_linked = self.links.len() == s.node.len();
        let on_satellite = |l: &NodeLinks| l.media.contains(&Medium::Satellite);
        if s.satellite.is_some() && every_node_linked && !self.links.values().any(on_satellite) {
            self.problem(
                "satellite",
                "no node has an Iridium link (DRIVER_IRIDIUM or DRIVER_IRIDIUM_SHORE, as its \
                 driver or a link's): give one a link on the satellite, or leave the section out",
            );
        }
        // A duration refused above is not checked against (no follow-on
        // problems of the faults).
        let run_s = if self.duration_s > 0.0 {
            self.duration_s + drain
        } else {
            f64::NAN
        };
        let faults = crate::fault::check(self, &s.fault, &s.node, run_s);
        Some(Scenario {
            seed: s.seed(),
            start_micros: start.ok()?,
            duration_micros: (duration * 1e6) as u64,
            drain_micros: (drain * 1e6) as u64,
            water,
            satellite,
            nodes: nodes?,
            faults,
            report: s.report.unwrap_or_default(),
        })
    }

    fn water(&mut self, water: &SimulatorDriverConfig) {
        let set_by_run = [
            ("water.node", !water.node.is_empty()),
            ("water.seed", water.seed.is_some()),
            ("water.channel", water.channel.is_some()),
            ("water.udp_local", water.udp_local.is_some()),
            ("water.udp_peer", !water.udp_peer.is_empty()),
        ];
        for (path, set) in set_by_run {
            if set {
                self.problem(
                    path,
                    "set by the scenario (node positions, the seed, one in-process channel): \
                     leave it out",
                );
            }
        }
        // The simulator driver's own checks, told as the scenario's water.
        let driver = crate::modem::driver_config(1, &[(1, [0.0; 3])], water, 0, None);
        // (The stand-in node's position is not the water's: each node's
        // place is checked in it apart.)
        let water_only = |p: &modemdriver::problem::Problem| !p.field.starts_with("simulator.node");
        for p in modemdriver::sim::problems(&driver)
            .into_iter()
            .filter(water_only)
        {
            let field = p.field.strip_prefix("simulator.").unwrap_or(&p.field);
            self.problem(format!("water.{field}"), p.reason.clone());
            self.water_refused.push(format!("driver.{}", p.field));
        }
    }

    /// The satellite's settings, as the simulator driver checks them.
    fn satellite(&mut self, satellite: &SatelliteLink) {
        let driver = crate::modem::satellite_config(1, &[(1, [0.0; 3])], satellite, 0, None);
        for p in modemdriver::sim::problems(&driver) {
            if let Some(field) = p.field.strip_prefix("simulator.satellite.") {
                self.problem(format!("satellite.{field}"), p.reason.clone());
                self.water_refused.push(format!("driver.{}", p.field));
            }
        }
    }

    /// The report's file names: plain names in the output directory, not
    /// the same one twice.
    fn report(&mut self, report: &pb::Report) {
        let names = [
            ("report.json", report.json()),
            ("report.csv", report.csv()),
            ("report.html", report.html()),
            ("report.links_csv", report.links_csv()),
            ("report.links_json", report.links_json()),
            ("report.replay", report.replay()),
        ];
        for (i, &(path, name)) in names.iter().enumerate() {
            let plain = Path::new(name)
                .file_name()
                .is_some_and(|f| f == std::ffi::OsStr::new(name));
            if !plain {
                self.problem(
                    path,
                    format!("\"{name}\" is not a file name (the files go in the --out directory)"),
                );
            } else if let Some((other, _)) = names[..i].iter().find(|(_, n)| *n == name) {
                self.problem(
                    path,
                    format!("\"{name}\" is {other}'s name too: give each output its own"),
                );
            }
        }
    }

    fn names_and_ids(&mut self, nodes: &[pb::Node]) {
        for (i, node) in nodes.iter().enumerate() {
            if node.name().trim().is_empty() {
                self.problem(format!("node[{i}].name"), "give the node a name");
            } else if node.name().contains("->") {
                // The report names a pair "a->b".
                self.problem(
                    format!("node[{i}].name"),
                    format!(
                        "{:?} holds \"->\", which the report puts between the names of a pair",
                        node.name()
                    ),
                );
            } else if let Some(c) = node
                .name()
                .chars()
                .find(|c| matches!(c, ',' | '"' | ';') || c.is_control())
            {
                // The name is a column of the ledger and links CSV files,
                // and `;` separates the packets' fates in them.
                self.problem(
                    format!("node[{i}].name"),
                    format!(
                        "{:?} holds {c:?}: a node's name is a column of the CSV files, \
                         so it holds no comma, double quote, semicolon or control character",
                        node.name()
                    ),
                );
            } else if let Some(j) = nodes[..i].iter().position(|n| n.name() == node.name()) {
                self.problem(
                    format!("node[{i}].name"),
                    format!("\"{}\" is node[{j}]'s name too", node.name()),
                );
            }
            match node.modem_id {
                None => self.problem(format!("node[{i}].modem_id"), "give the node's modem id"),
                Some(id) if id <= 0 => self.problem(
                    format!("node[{i}].modem_id"),
                    format!("{id} is not valid: modem ids are 1 and up (0 is broadcast)"),
                ),
                Some(id) => {
                    if let Some(j) = nodes[..i].iter().position(|n| n.modem_id == Some(id)) {
                        self.problem(
                            format!("node[{i}].modem_id"),
                            format!("{id} is node[{j}]'s modem id too"),
                        );
                    }
                }
            }
        }
    }

    fn node(&mut self, i: usize, node: &pb::Node, all: &[pb::Node]) -> Option<Node> {
        let place = self.place(i, node);
        let checked = self.gobyd(i, node)?;
        let mut traffic = Vec::new();
        for (j, t) in node.traffic.iter().enumerate() {
            traffic.push(self.traffic(i, j, t, node, all, &checked));
        }
        Some(Node {
            name: node.name().to_string(),
            modem_id: node.modem_id(),
            config: checked.config,
            codec: checked.codec,
            place: place?,
            traffic: traffic.into_iter().collect::<Option<Vec<_>>>()?,
            modem: self.modem_words(i),
            links: self
                .links
                .get(&i)
                .map(|l| l.media.clone())
                .unwrap_or_default(),
            satellite_link: self.links.get(&i).and_then(|l| l.satellite_link.clone()),
        })
    }

    /// Node `i`'s simulated modems in words: its modem on the water, its
    /// link on the satellite, or both (`"DRIVER_WHOI_MICROMODEM; iridium:
    /// Iridium SBD, simulated: …"`).
    fn modem_words(&self, i: usize) -> String {
        let water = self.modems.get(&i).map(|(_, words)| words.clone());
        let satellite = self.links.get(&i).and_then(|l| l.satellite_words.clone());
        match (water, satellite) {
            (Some(w), Some(s)) => format!("{w}; {s}"),
            (w, s) => w.or(s).unwrap_or_default(),
        }
    }

    /// Every node on the one water has the same modem: a Popoto does not
    /// hear a Micro-Modem (the simulator's own rates are the
    /// Micro-Modem's; a node whose modem's timing is not known has its
    /// modem all the same).
    fn one_modem_on_the_water(&mut self) {
        let named = |m: &Option<String>| {
            m.clone()
                .unwrap_or_else(|| crate::modem::SIMULATOR.to_string())
        };
        let family = |m: &Option<String>| match m.as_deref() {
            None | Some("DRIVER_WHOI_MICROMODEM") => None,
            Some(other) => Some(other.to_string()),
        };
        let Some((first, (modem, _))) = self.modems.first_key_value() else {
            return;
        };
        let (first, modem) = (*first, modem.clone());
        let other: Vec<(usize, Option<String>)> = self
            .modems
            .iter()
            .filter(|(_, (m, _))| family(m) != family(&modem))
            .map(|(i, (m, _))| (*i, m.clone()))
            .collect();
        for (i, m) in other {
            self.problem(
                format!("node[{i}].gobyd.driver"),
                format!(
                    "its modem is {}, node[{first}]'s {}: the nodes of a run share one \
                     water, and one kind of modem does not hear another's signals; give every \
                     node the same modem",
                    named(&m),
                    named(&modem)
                ),
            );
        }
    }

    /// Where node `i` is: its `position`, or its `track`.
    fn place(&mut self, i: usize, node: &pb::Node) -> Option<Place> {
        let at = format!("node[{i}]");
        match (&node.position, &node.track) {
            (Some(_), Some(_)) => {
                self.problem(
                    format!("{at}.track"),
                    "give position (a fixed node) or track (a moving one), not both",
                );
                None
            }
            (None, None) => {
                self.problem(
                    at,
                    "give the node's position { x y depth } (metres), or its track { waypoint { x y \
                     depth } ... speed_mps }",
                );
                None
            }
            (Some(p), None) => self.point(&format!("{at}.position"), p).map(Place::Fixed),
            (None, Some(track)) => self.track(&format!("{at}.track"), track).map(Place::Track),
        }
    }

    /// A position at `at`, checked: numbers, a depth of 0 or more, in the
    /// modelled water.
    fn point(&mut self, at: &str, position: &pb::Position) -> Option<[f64; 3]> {
        let before = self.found.len();
        for (axis, value) in [("x", position.x()), ("y", position.y())] {
            if !value.is_finite() {
                self.problem(
                    format!("{at}.{axis}"),
                    format!("{value} is not a position (metres)"),
                );
            } else if value.abs() > MAX_OFFSET {
                self.problem(
                    format!("{at}.{axis}"),
                    format!(
                        "{value:e} m is farther than {MAX_OFFSET:e} m from the origin: not a \
                         place on this planet's oceans in a local grid"
                    ),
                );
            }
        }
        let depth = position.depth();
        if !depth.is_finite() || depth < 0.0 {
            self.problem(
                format!("{at}.depth"),
                format!("{depth} is not a depth (metres down, 0 or more)"),
            );
        } else if depth > MAX_DEPTH {
            self.problem(
                format!("{at}.depth"),
                format!("{depth:e} m is deeper than any ocean ({MAX_DEPTH} m)"),
            );
        }
        let point = [position.x(), position.y(), depth];
        if self.found.len() == before && self.water.acoustic_channel.is_some() {
            // Where the modelled water has no room for a modem (under the
            // sea floor, out of the modelled range), as the driver says.
            let driver = crate::modem::driver_config(1, &[(1, point)], &self.water, 0, None);
            for p in modemdriver::sim::problems(&driver) {
                if p.field.starts_with("simulator.node[0]") {
                    self.problem(format!("{at}.depth"), p.reason.clone());
                }
            }
        }
        (self.found.len() == before).then_some(point)
    }

    /// A track at `at`, checked: its waypoints, and a speed a vehicle can
    /// go when it has somewhere to go.
    fn track(&mut self, at: &str, track: &pb::Track) -> Option<Track> {
        if track.waypoint.is_empty() {
            self.problem(format!("{at}.waypoint"), "give at least one waypoint");
            return None;
        }
        let waypoints: Vec<Option<[f64; 3]>> = track
            .waypoint
            .iter()
            .enumerate()
            .map(|(k, w)| self.point(&format!("{at}.waypoint[{k}]"), w))
            .collect();
        let waypoints: Vec<[f64; 3]> = waypoints.into_iter().collect::<Option<_>>()?;
        let speed = track.speed_mps();
        let needed = waypoints.len() > 1 || track.speed_mps.is_some();
        if needed && !(speed > 0.0 && speed <= MAX_SPEED) {
            self.problem(
                format!("{at}.speed_mps"),
                format!(
                    "{speed} is not a speed a node can go: metres per second, more than 0 and at \
                     most {MAX_SPEED}"
                ),
            );
            return None;
        }
        Some(Track {
            waypoints,
            speed,
            repeat: track.repeat(),
        })
    }

    /// The node's gobyd configuration, checked as the daemon will run it.
    fn gobyd(&mut self, i: usize, node: &pb::Node) -> Option<gobyd::check::Checked> {
        use pb::node::Config;
        let (config, file) = match &node.config {
            None => {
                self.problem(
                    format!("node[{i}]"),
                    "give the node's gobyd configuration: gobyd { ... } or gobyd_file",
                );
                return None;
            }
            // Read again as gobyd reads its file, so that Goby3's section
            // names (driver_cfg, mac_cfg, queue_cfg) and keys mean what
            // they mean there.
            Some(Config::Gobyd(config)) => {
                let text = config.transcode_to_dynamic().to_text_format();
                let origin = format!("{}: node[{i}].gobyd", self.origin);
                match gobyd::config::parse(&text, &origin) {
                    Ok(config) => (config, None),
                    Err(e) => {
                        self.found.push(format!("{e}"));
                        return None;
                    }
                }
            }
            Some(Config::GobydFile(name)) => {
                let path = self.base.join(name);
                let text = match std::fs::read_to_string(&path) {
                    Ok(text) => text,
                    Err(e) => {
                        self.problem(
                            format!("node[{i}].gobyd_file"),
                            format!("cannot read {}: {e}", path.display()),
                        );
                        return None;
                    }
                };
                let origin = path.display().to_string();
                match gobyd::config::parse(&text, &origin) {
                    Ok(config) => (config, Some((text, origin))),
                    Err(e) => {
                        self.found.push(format!("node[{i}].gobyd_file: {e}"));
                        return None;
                    }
                }
            }
        };
        // Paths in it are read relative to the file they are written in
        // (the gobyd file, or the scenario), not to where the run starts.
        let written_in = match &file {
            Some((_, origin)) => base_of(Path::new(origin)),
            None => self.base.to_path_buf(),
        };
        let config = relative_to(config, &written_in);
        let config = self.prepared(i, node, config, file.as_ref())?;
        match gobyd::check::validate(config, gobyd::config::DriverSettings::Configured) {
            Ok(checked) => Some(checked),
            Err(e) => {
                self.gobyd_refused(i, e, file);
                None
            }
        }
    }

    /// `config` as the node runs it: its modem id, the interfaces off. Its
    /// problems are told where they are written: in the scenario, or in
    /// `file` (its text and name).
    fn prepared(
        &mut self,
        i: usize,
        node: &pb::Node,
        mut config: GobydConfig,
        file: Option<&(String, String)>,
    ) -> Option<GobydConfig> {
        let id = node.modem_id.filter(|id| *id > 0)?;
        if config.modem_id.is_some_and(|own| own != id) {
            self.problem(
                format!("node[{i}].gobyd.modem_id"),
                format!("{} is not the node's modem_id ({id})", config.modem_id()),
            );
            return None;
        }
        config.modem_id = Some(id);
        // The simulator as the run starts it, so that its settings and the
        // slots against its packets are checked as `gobyd --check` checks
        // them (a slot too short for its rate's packet would drop every
        // transmission in it).
        let own = [(id, start_of(node))];
        let mut media = Vec::new();
        let mut satellite_link = None;
        let mut satellite_words = None;
        let mut on_water: Option<String> = None;
        let links: Vec<(String, Option<String>, &mut Option<DriverConfig>)> =
            match config.link.is_empty() {
                true => vec![("driver".into(), None, &mut config.driver)],
                false => config
                    .link
                    .iter_mut()
                    .enumerate()
                    .map(|(k, l)| (format!("link[{k}].driver"), l.name.clone(), &mut l.driver))
                    .collect(),
            };
        for (at, name, driver) in links {
            if crate::modem::is_satellite(driver.as_ref()) {
                if satellite_link.is_some() || media.contains(&Medium::Satellite) {
                    let reason = "a second Iridium link: a node has one link on the satellite";
                    self.config_problem(i, Problem::new(at, reason), file);
                    return None;
                }
                media.push(Medium::Satellite);
                let shore = crate::modem::is_shore(driver.as_ref());
                let words = crate::modem::satellite_words(&self.satellite, shore);
                satellite_words = Some(match &name {
                    Some(n) => format!("{n}: {words}"),
                    None => words,
                });
                satellite_link = name;
                *driver = Some(crate::modem::satellite_config(
                    id,
                    &own,
                    &self.satellite,
                    0,
                    driver.as_ref(),
                ));
                continue;
            }
            if let Some(first) = &on_water {
                let reason = format!(
                    "a second link on the water ({first} is one): a node has one modem on the \
                     water, and one link on the satellite (an Iridium driver)"
                );
                self.config_problem(i, Problem::new(at, reason), file);
                return None;
            }
            on_water = Some(name.unwrap_or_else(|| "its driver".into()));
            // The simulated modem sends as the node's own where it can.
            let sent = match crate::modem::sends_as(driver.as_ref()) {
                Ok(sent) => sent,
                Err(p) => {
                    let field = format!("{at}.{}", p.field);
                    self.config_problem(i, Problem::new(field, p.reason), file);
                    return None;
                }
            };
            let modem = sent.modem.clone();
            self.modems.insert(i, (sent.kind, sent.words));
            media.push(Medium::Water);
            *driver = Some(crate::modem::driver_config(
                id,
                &own,
                &self.water,
                0,
                modem.as_ref(),
            ));
        }
        self.links.insert(
            i,
            NodeLinks {
                media,
                satellite_link,
                satellite_words,
            },
        );
        // The run publishes and listens in-process: no JSON, MQTT or MOOS
        // interface, and no forecast (its ray traces run on other threads).
        config.json = Some(protos::goby::apps::protobuf::gobyd_config::JsonInterface {
            tcp_bind: Some(String::new()),
            udp_bind: Some(String::new()),
        });
        config.mqtt = None;
        config.moos = None;
        config.forecast = None;
        Some(config)
    }

    /// Reports gobyd's refusal of node `i`'s configuration, each problem
    /// where it is written: in the scenario (inline) or in `file`.
    fn gobyd_refused(&mut self, i: usize, e: DaemonError, file: Option<(String, String)>) {
        let DaemonError::Config(ConfigError::Problems(problems)) = e else {
            let path = match file {
                Some(_) => "gobyd_file",
                None => "gobyd",
            };
            self.problem(format!("node[{i}].{path}"), e.to_string());
            return;
        };
        for p in problems {
            // A link's driver is told as the top-level one is.
            let bare = match p.field.strip_prefix("link[") {
                Some(rest) => rest.split_once("].").map_or(p.field.as_str(), |(_, f)| f),
                None => p.field.as_str(),
            };
            if self.water_refused.iter().any(|f| f == bare) {
                continue;
            }
            self.config_problem(i, p, file.as_ref());
        }
    }

    /// A problem `p` of node `i`'s gobyd configuration (its field a path in
    /// that configuration), told where it is written: in the scenario
    /// (inline), or at its line in `file` (its text and name).
    fn config_problem(&mut self, i: usize, mut p: Problem, file: Option<&(String, String)>) {
        match file {
            None => self.problem(format!("node[{i}].gobyd.{}", p.field), p.reason),
            Some((text, origin)) => {
                gobyd::config::locate(std::slice::from_mut(&mut p), text, origin);
                let place = p.place.as_deref().unwrap_or(origin);
                self.found.push(format!(
                    "{place}: {}: {} (node[{i}].gobyd_file)",
                    p.field, p.reason
                ));
            }
        }
    }

    fn traffic(
        &mut self,
        i: usize,
        j: usize,
        t: &pb::Traffic,
        node: &pb::Node,
        all: &[pb::Node],
        checked: &gobyd::check::Checked,
    ) -> Option<Stream> {
        let at = format!("node[{i}].traffic[{j}]");
        let descriptor = match checked.codec.descriptor(t.r#type()) {
            Some(d) => d,
            None => {
                self.problem(
                    format!("{at}.type"),
                    format!(
                        "\"{}\" is not a type node \"{}\"'s gobyd loads (it loads {})",
                        t.r#type(),
                        node.name(),
                        checked.loaded.join(", ")
                    ),
                );
                return None;
            }
        };
        let rate = self.rate(&at, t)?;
        let dest = match &t.dest {
            None => None,
            Some(name) => match all.iter().position(|n| n.name() == name) {
                None => {
                    self.problem(format!("{at}.dest"), format!("no node named \"{name}\""));
                    return None;
                }
                Some(d) if all[d].modem_id == node.modem_id => {
                    self.problem(format!("{at}.dest"), "a node does not send to itself");
                    return None;
                }
                Some(d) => Some((d, all[d].modem_id())),
            },
        };
        let mut fixed = Vec::new();
        let roles = role_fields(checked, &descriptor);
        if let Some(field) = roles.source.as_ref() {
            fixed.push((field.clone(), modem_id_value(node.modem_id())));
        }
        match (&dest, roles.destination.clone()) {
            (Some((_, id)), Some(field)) => fixed.push((field, modem_id_value(*id))),
            (Some(_), None) => {
                self.problem(
                    format!("{at}.dest"),
                    format!(
                        "{} has no DESTINATION_ID role in node \"{}\"'s queue: it is sent to \
                         every node (leave dest out)",
                        descriptor.full_name(),
                        node.name()
                    ),
                );
                return None;
            }
            // Sent to every node: the destination role says broadcast (0).
            (None, Some(field)) => fixed.push((field, modem_id_value(0))),
            (None, None) => {}
        }

        let before = self.found.len();
        for (k, field) in t.field.iter().enumerate() {
            if let Some(first) = t.field[..k].iter().position(|f| f.name() == field.name()) {
                self.problem(
                    format!("{at}.field[{k}].name"),
                    format!("{} is given by field[{first}] already", field.name()),
                );
                continue;
            }
            let role = [
                (&roles.source, "SOURCE_ID", "the sending node's modem id"),
                (
                    &roles.destination,
                    "DESTINATION_ID",
                    "the modem id of dest (0 without dest)",
                ),
            ]
            .into_iter()
            .find(|(f, _, _)| f.as_ref().is_some_and(|f| f.name() == field.name()));
            if let Some((_, role, what)) = role {
                self.problem(
                    format!("{at}.field[{k}].name"),
                    format!(
                        "{} is the {role} role of {}'s queue entry: the run sets it to {what}",
                        field.name(),
                        descriptor.full_name()
                    ),
                );
                continue;
            }
            match crate::traffic::field_value(&descriptor, field) {
                Ok(value) => fixed.push(value),
                Err((part, reason)) => self.problem(format!("{at}.field[{k}]{part}"), reason),
            }
        }
        if self.found.len() > before {
            return None;
        }
        let start_s = t.start_s();
        if !(start_s >= 0.0 && start_s.is_finite()) {
            self.problem(
                format!("{at}.start_s"),
                format!("{start_s} is not 0 or more seconds"),
            );
            return None;
        }
        if self.duration_s > 0.0 && start_s >= self.duration_s {
            self.problem(
                format!("{at}.start_s"),
                format!(
                    "{start_s} s is not before the traffic ends (duration_s {} s): the stream \
                     would publish nothing",
                    self.duration_s
                ),
            );
            return None;
        }
        let clamped = checked
            .queue
            .message_entry
            .iter()
            .any(|e| e.protobuf_name == descriptor.full_name() && e.clamp_out_of_range());
        let stream = Stream {
            index: j,
            descriptor,
            dest: dest.map(|(d, _)| d),
            rate,
            start_s,
            fields: fixed,
        };
        if let Some(problem) = first_message_problem(&stream, i, checked, clamped, self.start_s) {
            self.problem(at, format!("its first message is refused: {problem}"));
            return None;
        }
        Some(stream)
    }

    fn rate(&mut self, at: &str, t: &pb::Traffic) -> Option<Rate> {
        use pb::traffic::Rate as R;
        let (path, value, rate) = match t.rate {
            None => {
                self.problem(at, "give period_s or poisson_per_hour");
                return None;
            }
            Some(R::PeriodS(p)) => ("period_s", p, Rate::Period(p)),
            Some(R::PoissonPerHour(r)) => ("poisson_per_hour", r, Rate::Poisson(r)),
        };
        if !(value > 0.0 && value.is_finite()) {
            self.problem(
                format!("{at}.{path}"),
                format!("{value} is not more than 0"),
            );
            return None;
        }
        let count = match rate {
            Rate::Period(p) => self.duration_s / p,
            Rate::Poisson(per_hour) => per_hour * self.duration_s / 3600.0,
        };
        if count > MAX_PUBLICATIONS {
            self.problem(
                format!("{at}.{path}"),
                format!(
                    "{value} makes about {count:.0} publications in duration_s: at most \
                     {MAX_PUBLICATIONS} per stream"
                ),
            );
            return None;
        }
        Some(rate)
    }
}

/// Where `node` is at the start, as written (its position, or its
/// track's first waypoint; the origin when it has neither, which is
/// refused apart).
fn start_of(node: &pb::Node) -> [f64; 3] {
    let p = node
        .position
        .or_else(|| {
            node.track
                .as_ref()
                .and_then(|t| t.waypoint.first().copied())
        })
        .unwrap_or_default();
    [p.x(), p.y(), p.depth()]
}

/// `config` with its `.proto` files and include directories that are
/// relative paths taken relative to `dir`.
fn relative_to(mut config: GobydConfig, dir: &Path) -> GobydConfig {
    if let Some(dccl) = config.dccl.as_mut() {
        for path in dccl
            .proto_file
            .iter_mut()
            .chain(dccl.include_dir.iter_mut())
        {
            if Path::new(path.as_str()).is_relative() {
                *path = dir.join(path.as_str()).display().to_string();
            }
        }
    }
    config
}

/// The fields a type's queue entry gives the source and destination
/// roles (by field value).
struct Roles {
    source: Option<prost_reflect::FieldDescriptor>,
    destination: Option<prost_reflect::FieldDescriptor>,
}

fn role_fields(checked: &gobyd::check::Checked, descriptor: &MessageDescriptor) -> Roles {
    let entry = checked
        .queue
        .message_entry
        .iter()
        .find(|e| e.protobuf_name == descriptor.full_name());
    let field = |kind: RoleType| {
        let role = entry?
            .role
            .iter()
            .find(|r| r.r#type() == kind && r.setting() == RoleSetting::FieldValue)?;
        descriptor.get_field_by_name(role.field())
    };
    Roles {
        source: field(RoleType::SourceId),
        destination: field(RoleType::DestinationId),
    }
}

/// `text` (RFC 3339) as microseconds since the UNIX epoch.
fn start_micros(text: &str) -> Result<i64, String> {
    let at = time::OffsetDateTime::parse(text, &time::format_description::well_known::Rfc3339)
        .map_err(|e| format!("\"{text}\" is not an RFC 3339 time (2026-06-01T00:00:00Z): {e}"))?;
    i64::try_from(at.unix_timestamp_nanos() / 1000)
        .map_err(|_| format!("\"{text}\" is out of range"))
}

/// Where a scenario file's relative paths are read from.
pub fn base_of(path: &Path) -> PathBuf {
    path.parent().map(Path::to_path_buf).unwrap_or_default()
}

/// A modem id as a field's value, the same in every message.
fn modem_id_value(id: i32) -> ValueGen {
    ValueGen::Counter {
        start: i64::from(id),
        step: 0,
        format: "%d".into(),
    }
}

/// Why the first message of `stream` (of node `node`) would be refused at
/// publication, if it would: a required field left out, a value out of
/// its field's range (unless its queue entry clamps), a time the receiver
/// would restore on another date than `start_s`'s.
fn first_message_problem(
    stream: &Stream,
    node: usize,
    checked: &gobyd::check::Checked,
    clamped: bool,
    start_s: Option<i64>,
) -> Option<String> {
    // One publication made and encoded now: a required field left out,
    // a value out of its field's range, is refused before the run.
    // A time the receiver would restore on another date (the daemon
    // refuses it at publication), checked at the start.
    let sample = stream.generator(0, node).message();
    let moved = match start_s {
        Some(start_s) => checked.codec.moved_dates_at(&sample, start_s),
        None => Ok(Vec::new()),
    };
    let changed = checked
        .codec
        .check(&sample)
        .map(|changes| if clamped { Vec::new() } else { changes });
    let problem = match (checked.codec.encode(&sample), moved, changed) {
        (Err(e), _, _) | (Ok(_), Err(e), _) | (Ok(_), _, Err(e)) => Some(e.to_string()),
        (Ok(_), Ok(moved), Ok(changed)) => moved.first().or(changed.first()).map(|c| {
            format!(
                "field {}: {} (the daemon refuses a value its type cannot carry unless the \
                 queue entry says clamp_out_of_range: true)",
                c.field, c.reason
            )
        }),
    };
    problem
}
