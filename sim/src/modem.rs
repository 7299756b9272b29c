//! The simulated modem each node of a run has: the acoustic channel
//! simulator's driver section, from the scenario's water and the nodes'
//! places (what the run starts, and what the scenario is checked with).

use protos::goby::acomms::protobuf::{
    driver_config, simulator_driver_config::NodePosition, DriverConfig, DriverType, SatelliteLink,
    SimulatorDriverConfig,
};

/// The driver section of node `modem_id`: the acoustic channel simulator
/// with the scenario's `water`, every node at `positions` (modem id; x,
/// y, depth in metres), its losses drawn from `seed`; acks deferred to the
/// daemon (sent once the message is recorded). With `modem` (a section
/// [`sends_as`] made), the simulated modem sends as that one.
pub fn driver_config(
    modem_id: i32,
    positions: &[(i32, [f64; 3])],
    water: &SimulatorDriverConfig,
    seed: u64,
    modem: Option<&DriverConfig>,
) -> DriverConfig {
    let mut simulator = water.clone();
    simulator.modem = modem
        .and_then(|m| m.simulator.as_ref())
        .and_then(|s| s.modem.clone());
    simulator.node = positions
        .iter()
        .map(|(id, [x, y, depth])| NodePosition {
            modem_id: *id,
            x: Some(*x),
            y: Some(*y),
            z: Some(-depth),
        })
        .collect();
    simulator.seed = Some(seed);
    DriverConfig {
        driver: Some(driver_config::Driver::DriverType(
            DriverType::DriverAcousticSimulator as i32,
        )),
        modem_id: Some(modem_id),
        deferred_ack: Some(true),
        simulator: Some(simulator),
        // The modem's own settings (its frame size), which the simulator
        // reads as that modem's.
        ..modem.cloned().unwrap_or_default()
    }
}

/// The simulated modem of a node whose driver names no modem the
/// simulator sends as, in words.
pub const SIMULATOR: &str = "the simulator's (Micro-Modem rates)";

/// What a node's own driver section `driver` makes of its simulated
/// modem: the section to give [`driver_config()`] when the simulator can
/// send as that modem (its settings kept, `simulator.modem` naming it),
/// and the modem in words for the report (`"DRIVER_POPOTO"`, `"the
/// simulator's (Micro-Modem rates)"`, or why the modem's own timing is not
/// simulated), and the modem's kind (`None`: the simulator's own).
///
/// # Errors
/// The problem of a section that names no driver built in (a misspelled
/// `driver_name`), as `gobyd --check` says it.
pub fn sends_as(driver: Option<&DriverConfig>) -> Result<SentAs, modemdriver::problem::Problem> {
    let simulator = SentAs {
        modem: None,
        words: SIMULATOR.to_string(),
        kind: None,
    };
    let Some(driver) = driver.filter(|d| d.driver.is_some()) else {
        return Ok(simulator);
    };
    let kind = modemdriver::built_in::of(driver)?;
    let name = kind.about().named.name();
    if kind.about().named == modemdriver::kind::Named::Type(DriverType::DriverAcousticSimulator) {
        // The node's own simulator settings: the modem it names, if any.
        return Ok(
            match driver.simulator.as_ref().and_then(|s| s.modem.clone()) {
                Some(modem) => SentAs {
                    modem: Some(driver.clone()),
                    words: modem.clone(),
                    kind: Some(modem),
                },
                None => simulator,
            },
        );
    }
    let mut own = driver.clone();
    own.simulator.get_or_insert_with(Default::default).modem = Some(name.to_string());
    Ok(match modemdriver::sim::modem_of(&own) {
        Ok(Some(_)) => SentAs {
            modem: Some(own),
            words: name.to_string(),
            kind: Some(name.to_string()),
        },
        _ => SentAs {
            modem: None,
            words: format!("{SIMULATOR}: {name}'s timing is not known here"),
            kind: Some(name.to_string()),
        },
    })
}

/// A node's simulated modem ([`sends_as`]).
#[derive(Debug, Clone)]
pub struct SentAs {
    /// The driver section to give [`driver_config()`] (`None`: the
    /// simulator's own rates).
    pub modem: Option<DriverConfig>,
    /// In words, for the report.
    pub words: String,
    /// The modem the node's configuration names (`None`: none, or the
    /// simulator without one), whether or not it is sent as.
    pub kind: Option<String>,
}

/// Whether `driver` is an Iridium modem's or shore station's
/// (`DRIVER_IRIDIUM`, `DRIVER_IRIDIUM_SHORE`): the run puts its link on
/// the satellite, not on the water.
pub fn is_satellite(driver: Option<&DriverConfig>) -> bool {
    let iridium = [DriverType::DriverIridium, DriverType::DriverIridiumShore];
    matches!(
        driver.and_then(|d| d.driver.as_ref()),
        Some(driver_config::Driver::DriverType(t))
            if iridium.iter().any(|i| *i as i32 == *t)
    )
}

/// Whether `driver` is a shore station's (`DRIVER_IRIDIUM_SHORE`): on the
/// gateway's side of the satellite, reached wherever it is placed.
pub fn is_shore(driver: Option<&DriverConfig>) -> bool {
    let shore = DriverType::DriverIridiumShore as i32;
    driver.and_then(|d| d.driver.as_ref()) == Some(&driver_config::Driver::DriverType(shore))
}

/// The driver section of node `modem_id`'s satellite link: the simulator
/// on `satellite`, every node at `positions` (their depths decide who
/// sees the satellites; a shore station, `DRIVER_IRIDIUM_SHORE`, is
/// reached at any depth), its losses drawn from `seed`; acks deferred to
/// the daemon. A session's frame is `satellite.frame_bytes` when given,
/// else the largest the node's own Iridium section `own` sends (329 bytes
/// MO from a 9602/9603, 259 MT from a shore).
pub fn satellite_config(
    modem_id: i32,
    positions: &[(i32, [f64; 3])],
    satellite: &SatelliteLink,
    seed: u64,
    own: Option<&DriverConfig>,
) -> DriverConfig {
    let mut link = *satellite;
    if is_shore(own) {
        // A shore station is on the gateway's side (DirectIP, RUDICS over
        // the Internet): reached wherever the scenario places it.
        link.shore = Some(true);
    }
    if link.frame_bytes.is_none() {
        // The node's own driver's frame each way: what it sends.
        link.frame_bytes = own
            .and_then(modemdriver::check::frame_limits)
            .and_then(|l| u32::try_from(l.outgoing).ok());
    }
    if link.frame_bytes.is_none() {
        link.frame_bytes = own
            .and_then(modemdriver::check::largest_frame)
            .and_then(|b| u32::try_from(b).ok());
    }
    let water = SimulatorDriverConfig {
        satellite: Some(link),
        ..Default::default()
    };
    driver_config(modem_id, positions, &water, seed, None)
}

/// A satellite link in words, for the report: a vehicle's (`shore`
/// false) or a shore station's, which makes no sessions.
pub fn satellite_words(satellite: &SatelliteLink, shore: bool) -> String {
    let gateway = format!(
        "{} s through the gateway (at most {} messages a node held there)",
        satellite.latency_seconds(),
        satellite.queue_limit()
    );
    if shore {
        return format!(
            "Iridium SBD, simulated: a shore station on the gateway's side, without sessions, \
             reached anywhere; {gateway}"
        );
    }
    let failing = match (satellite.session_failure(), satellite.taken_when_failed()) {
        (f, _) if f <= 0.0 => String::new(),
        (f, t) if t <= 0.0 => format!(", {} % of them failing", f * 100.0),
        (f, t) => format!(
            ", {} % of them failing ({} % of those after the gateway took the message)",
            f * 100.0,
            t * 100.0
        ),
    };
    format!(
        "Iridium SBD, simulated: sessions of {} s{failing}, {gateway}, from and to antennas at \
         most {} m deep",
        satellite.session_seconds(),
        satellite.surface_depth()
    )
}

/// A simulator driver section made by [`satellite_config`] for the
/// scenario's check, with every node at `positions` and its losses drawn
/// from `seed`, as the run starts it.
pub fn placed(section: &DriverConfig, positions: &[(i32, [f64; 3])], seed: u64) -> DriverConfig {
    let water = section.simulator.clone().unwrap_or_default();
    driver_config(
        section.modem_id(),
        positions,
        &SimulatorDriverConfig {
            modem: None,
            ..water
        },
        seed,
        None,
    )
}
