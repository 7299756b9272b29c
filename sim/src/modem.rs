//! The simulated modem each node of a run has: the acoustic channel
//! simulator's driver section, from the scenario's water and the nodes'
//! places (what the run starts, and what the scenario is checked with).

use protos::goby::acomms::protobuf::{
    driver_config, simulator_driver_config::NodePosition, DriverConfig, DriverType,
    SimulatorDriverConfig,
};

/// The driver section of node `modem_id`: the acoustic channel simulator
/// with the scenario's `water`, every node at `positions` (modem id; x,
/// y, depth in metres), its losses drawn from `seed`; acks deferred to the
/// daemon (sent once the message is recorded).
pub fn driver_config(
    modem_id: i32,
    positions: &[(i32, [f64; 3])],
    water: &SimulatorDriverConfig,
    seed: u64,
) -> DriverConfig {
    let mut simulator = water.clone();
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
        ..Default::default()
    }
}
