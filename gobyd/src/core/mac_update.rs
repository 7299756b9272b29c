//! The core's side of changes to the TDMA cycle made at sea: a
//! `MACUpdate` (Goby3's, see [`amac::update`]) from MOOS, JSON, MQTT or
//! the link is applied to the first link's medium access control when its
//! `dest` is this node, kept in the data directory
//! ([`MacCycleFile`]) before it takes effect, and told on the `mac`
//! events; the cycle kept is restored at start.

use protos::goby::acomms::protobuf::{MacConfig, MacCycle, MacUpdate, ModemTransmission};

use super::link::mac_cycle::{Kept, MacCycleFile};
use super::Core;
use crate::event::{ModemEvent, UpdateSource};

/// The medium access settings the configuration gives the first link.
pub(super) fn configured_mac(config: &protos::goby::apps::protobuf::GobydConfig) -> MacConfig {
    crate::config::links::links(config)
        .first()
        .and_then(|v| v.mac)
        .cloned()
        .unwrap_or_default()
}

/// Why the first link's driver cannot run `slots` (as `--check` tells it
/// for the configured cycle), in one line; `None`: it can.
fn driver_problems(core: &Core, slots: &[ModemTransmission]) -> Option<String> {
    let driver = core.links[0]
        .config
        .as_ref()
        .or(core.configured_driver.as_ref())?;
    let problems = crate::config::cycle_problems(&core.configured_mac, slots, driver);
    (!problems.is_empty()).then(|| {
        let each: Vec<String> = problems.iter().map(|p| p.to_string()).collect();
        format!("the cycle after the update cannot run: {}", each.join("; "))
    })
}

impl Core {
    /// The first link's cycle as it stands.
    pub(super) fn mac_cycle(&self) -> MacCycle {
        let mac = &self.links[0].mac;
        MacCycle {
            slot: mac.cycle(),
            running: Some(mac.running()),
            modem_id: Some(mac.modem_id()),
            configured_slot: Vec::new(),
        }
    }

    /// Runs the cycle kept in the data directory, if it was kept for this
    /// configuration (what happens is logged).
    pub(super) fn restore_mac_cycle(&mut self) {
        let file = MacCycleFile::in_dir(self.data_dir.path());
        let kept = file.load(self.modem_id, &self.configured_mac.slot);
        let now = self.clock.now();
        match kept {
            Ok(Kept::Nothing) => {}
            Ok(Kept::Stale(why)) => tracing::warn!(
                "{}: not used ({why}); the configured TDMA cycle runs",
                file.path().display()
            ),
            Ok(Kept::Cycle(cycle)) => {
                let mac = &mut self.links[0].mac;
                match mac.set_slots(cycle.slot.clone(), now) {
                    Ok(()) => {
                        mac.set_running(cycle.running(), now);
                        tracing::info!(
                            slots = cycle.slot.len(),
                            running = cycle.running(),
                            "the TDMA cycle changed before the restart runs ({})",
                            file.path().display()
                        );
                    }
                    Err(e) => tracing::error!(
                        "{}: {e}; the configured TDMA cycle runs",
                        file.path().display()
                    ),
                }
            }
            Err(e) => tracing::error!("{e}; the configured TDMA cycle runs"),
        }
    }

    /// Applies `update` to the first link's cycle (see the module's
    /// documentation): the cycle after it, or why it was not applied (for
    /// another node, an index outside the cycle, a slot that cannot run,
    /// the change could not be kept on disk). Told on the `mac` events
    /// and in the log either way.
    pub(super) fn mac_update(
        &mut self,
        update: &MacUpdate,
        from: UpdateSource,
    ) -> Result<MacCycle, String> {
        let now = self.clock.now();
        let mut mac = self.links[0].mac.clone();
        let applied = mac.apply_update(update, now).map_err(|e| e.to_string());
        let applied = applied.and_then(|outcome| match driver_problems(self, &outcome.cycle) {
            Some(problem) => Err(problem),
            None => Ok(outcome),
        });
        let kept = applied.and_then(|outcome| {
            let cycle = MacCycle {
                slot: outcome.cycle,
                running: Some(outcome.running),
                modem_id: Some(self.modem_id),
                configured_slot: self.configured_mac.slot.clone(),
            };
            MacCycleFile::in_dir(self.data_dir.path())
                .save(&cycle)
                .map_err(|e| format!("the change could not be kept: {e}"))
        });
        if let Err(e) = kept {
            tracing::warn!(from = from.name(), "MAC cycle update not applied: {e}");
            self.report(
                0,
                ModemEvent::MacCycle {
                    cycle: self.mac_cycle(),
                    update: Some(update.clone()),
                    from: from.name(),
                    error: Some(e.clone()),
                },
            );
            return Err(e);
        }
        self.links[0].mac = mac;
        let cycle = self.mac_cycle();
        tracing::info!(
            from = from.name(),
            slots = cycle.slot.len(),
            running = cycle.running(),
            "MAC cycle updated: {}",
            dccl_text(update)
        );
        self.report(
            0,
            ModemEvent::MacCycle {
                cycle: cycle.clone(),
                update: Some(update.clone()),
                from: from.name(),
                error: None,
            },
        );
        Ok(cycle)
    }
}

/// An update in protobuf text format, for the log.
fn dccl_text(update: &MacUpdate) -> String {
    use prost_reflect::ReflectMessage;
    dccl::short_debug_string(&update.transcode_to_dynamic())
}
