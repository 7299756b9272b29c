//! Two emulated WHOI Micro-Modems on real pseudo-terminals, their packets
//! on an in-process acoustic simulator, for the tests that run `gobyd` over
//! them; the Micro-Modem driver's configuration for them; the check that
//! each modem kept its TDMA slot.

#![allow(dead_code)]

use std::path::Path;
use std::time::Duration;

use emulators::micromodem::{
    self as emulator, AirKind, AirTime, Dialect, EmulatorConfig, EmulatorFaults, EmulatorHandle,
    EmulatorPort,
};
use modemdriver::sim::{medium::Medium, SimulatorDriver};
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::SimulatorDriverConfig;

use super::node::MicroModem;

/// The path of modem `id`'s pseudo-terminal (a symbolic link kept by its
/// emulator) in `dir`.
pub fn modem_path(dir: &Path, id: u32) -> std::path::PathBuf {
    dir.join(format!("modem{id}"))
}

/// Two emulated modems (ids 1 and 2) 300 m apart on an in-process channel,
/// speaking `dialect`, each on a pseudo-terminal at [`modem_path`]. Must be
/// called within a Tokio runtime (the emulators are its tasks).
pub fn start_emulators(
    dir: &Path,
    dialect: Dialect,
    faults: EmulatorFaults,
) -> Vec<EmulatorHandle> {
    let medium = Medium::new();
    (1..=2u32)
        .map(|id| start_emulator(dir, id, &medium, dialect, faults))
        .collect()
}

/// Emulated modem `id` (1 or 2, the two 300 m apart) on `medium`, speaking
/// `dialect`, on a pseudo-terminal at [`modem_path`]: one of
/// [`start_emulators`]'s, or one started again on the same channel after
/// it was stopped (a modem that died and came back). Must be called within
/// a Tokio runtime.
pub fn start_emulator(
    dir: &Path,
    id: u32,
    medium: &std::sync::Arc<Medium>,
    dialect: Dialect,
    faults: EmulatorFaults,
) -> EmulatorHandle {
    let node: Vec<NodePosition> = (1..=2)
        .map(|m| NodePosition {
            modem_id: m,
            x: Some(f64::from(m - 1) * 300.0),
            ..Default::default()
        })
        .collect();
    let config = modemdriver::DriverConfig {
        modem_id: Some(id as i32),
        simulator: Some(SimulatorDriverConfig {
            node,
            packet_overhead_seconds: Some(0.05),
            ..Default::default()
        }),
        ..Default::default()
    };
    let backend = SimulatorDriver::start_on(&config, medium.clone()).unwrap();
    let base = match dialect {
        Dialect::MicroModem2 => EmulatorConfig::micromodem2(id),
        Dialect::MicroModem1 => EmulatorConfig::default(),
    };
    let emulated = EmulatorConfig {
        modem_id: id,
        packet_overhead: Duration::from_millis(300),
        faults,
        ..base
    };
    let port = EmulatorPort::Pty {
        link: Some(modem_path(dir, id)),
    };
    emulator::start(emulated, port, Some(backend)).expect("emulator starts")
}

/// The Micro-Modem driver of a `gobyd` configuration for an emulated
/// modem at `link`: reconnected every 300 ms, answers awaited 600 ms,
/// receptions 2500 ms (`micromodem { reconnect_interval_ms: 300
/// response_timeout_ms: 600 receive_timeout_ms: 2500 }`).
pub fn micromodem_driver(link: &Path) -> MicroModem {
    MicroModem::new(link)
        .setting("reconnect_interval_ms: 300")
        .setting("response_timeout_ms: 600")
        .setting("receive_timeout_ms: 2500")
}

/// Checks every data packet of modem i (slot i-1) lies in its slot of the
/// cycle (slots counted from the start of the UTC day); returns the report,
/// starting `slots: N outside`.
pub fn slot_report(air: &[Vec<AirTime>], slot_seconds: f64) -> String {
    if air.is_empty() {
        return "slots: not observed (no modem emulator)".into();
    }
    let slot = (slot_seconds * 1e6) as u64;
    let cycle = slot * air.len() as u64;
    let mut parts = Vec::new();
    let mut outside = 0;
    for (i, packets) in air.iter().enumerate() {
        let own = i as u64 * slot;
        let mut earliest = u64::MAX;
        let mut latest_end = 0;
        let mut data = 0;
        let mut aborted = 0;
        for p in packets {
            if p.kind == AirKind::Ack {
                continue;
            }
            if p.kind == AirKind::Aborted {
                aborted += 1;
            }
            data += 1;
            let offset = p.start % cycle;
            let end_offset = offset + (p.end - p.start);
            if offset < own || end_offset > own + slot {
                outside += 1;
                eprintln!(
                    "modem {}: packet at {:.3}..{:.3} s of the cycle, outside its slot {:.0}..{:.0} s",
                    i + 1,
                    offset as f64 / 1e6,
                    end_offset as f64 / 1e6,
                    own as f64 / 1e6,
                    (own + slot) as f64 / 1e6
                );
            }
            earliest = earliest.min(offset - own.min(offset));
            latest_end = latest_end.max(end_offset.saturating_sub(own));
        }
        parts.push(format!(
            "modem {}: {data} packets ({aborted} aborted), on the water from +{:.2} s to +{:.2} s of its {slot_seconds} s slot",
            i + 1,
            if data > 0 { earliest as f64 / 1e6 } else { 0.0 },
            latest_end as f64 / 1e6
        ));
    }
    format!("slots: {} outside; {}", outside, parts.join("; "))
}
