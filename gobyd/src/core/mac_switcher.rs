//! The core's side of the MAC switcher (`mac_switcher` in the
//! configuration, [`amac::switcher`]): a request from JSON, MQTT or MOOS
//! switches the first link to a named MAC, optionally with a keep-alive;
//! when the keep-alive runs out the default MAC runs again at once (the
//! core wakes for the deadline as for a slot). Each switch is kept in the
//! data directory ([`MacSwitchFile`]) before it takes effect and told on
//! the `mac` events (`mac_switch`, with its reason, and, for a switch to
//! another MAC, `mac_cycle` with the cycle it runs); the state kept is
//! restored at start, going back to the default when the deadline passed
//! while the daemon was down.
//!
//! A switch to another MAC runs it as configured: the changes made by
//! `MACUpdate`s to the MAC that ran before are dropped (and their file
//! removed).

use std::collections::HashMap;

use amac::{MacManager, Switch, Switcher};
use gobyd_protocol::mac_switch::MacSwitchState;
use protos::goby::acomms::protobuf::{MacConfig, MacSwitchState as KeptState};
use protos::goby::apps::protobuf::GobydConfig;

use super::link::mac_cycle::MacCycleFile;
use super::link::mac_switch::MacSwitchFile;
use super::Core;
use crate::event::{MacSwitched, ModemEvent, UpdateSource};

/// The switcher of a configuration, with each MAC by name (`None`: no
/// `mac_switcher`). The configuration is completed and checked.
#[derive(Debug, Clone)]
pub(super) struct MacSwitcher {
    switcher: Switcher,
    macs: HashMap<String, MacConfig>,
}

impl MacSwitcher {
    /// The switcher of `config`, running its default.
    pub(super) fn of(config: &GobydConfig) -> Option<Self> {
        let section = config.mac_switcher.as_ref()?;
        let names: Vec<String> = section.mac.iter().map(|m| m.name().to_string()).collect();
        let switcher = Switcher::new(names, section.default_mac())?;
        let macs = section
            .mac
            .iter()
            .map(|m| (m.name().to_string(), m.mac.clone().unwrap_or_default()))
            .collect();
        Some(MacSwitcher { switcher, macs })
    }
}

/// The longest keep-alive, seconds: a year. A keep-alive is renewed by the
/// process commanding the MAC; for one that never lapses, give none.
const MAX_KEEP_ALIVE_SECONDS: f64 = 366.0 * 86_400.0;

/// Microseconds of `seconds` (a keep-alive), or why not.
fn keep_alive_micros(seconds: Option<f64>) -> Result<Option<i64>, String> {
    match seconds {
        None => Ok(None),
        Some(s) if s.is_finite() && s > 0.0 && s <= MAX_KEEP_ALIVE_SECONDS => {
            Ok(Some((s * 1e6).round() as i64))
        }
        Some(s) if s > MAX_KEEP_ALIVE_SECONDS => Err(format!(
            "keep_alive_seconds {s} is more than a year ({MAX_KEEP_ALIVE_SECONDS} s): leave it \
             out for a MAC that runs until switched again"
        )),
        Some(s) => Err(format!(
            "keep_alive_seconds {s} is not a positive number of seconds (leave it out for no keep-alive)"
        )),
    }
}

impl Core {
    /// Which MAC runs (`Err`: the configuration has no switcher).
    pub(super) fn mac_switch_state(&self) -> Result<MacSwitchState, String> {
        let s = &self
            .mac_switcher
            .as_ref()
            .ok_or("no MAC switcher: give mac_switcher in the configuration")?
            .switcher;
        Ok(MacSwitchState {
            active: s.active().to_string(),
            default_mac: s.default_name().to_string(),
            macs: s.names().to_vec(),
            keep_alive_until: s.until().map(|u| u as f64 / 1e6),
        })
    }

    /// When the running MAC's keep-alive runs out (microseconds since the
    /// epoch), for the core's wake-up.
    pub(super) fn mac_switch_deadline(&self) -> Option<i64> {
        self.mac_switcher.as_ref()?.switcher.until()
    }

    /// Switches to `mac` (see [`Control::MacSwitch`](crate::event::Control::MacSwitch)):
    /// which MAC runs after it, or why not (no switcher, no MAC of that
    /// name, a keep-alive that is not positive, the state could not be
    /// kept on disk). Told on the `mac` events and in the log either way.
    pub(super) fn mac_switch(
        &mut self,
        mac: Option<String>,
        keep_alive_seconds: Option<f64>,
        from: UpdateSource,
    ) -> Result<MacSwitchState, String> {
        let Some(name) = mac else {
            return self.mac_switch_state();
        };
        let now = self.clock.now();
        let Some(current) = self.mac_switcher.clone() else {
            return self.mac_switch_state();
        };
        let mut next = current.switcher.clone();
        let switched = keep_alive_micros(keep_alive_seconds)
            .and_then(|k| next.request(&name, k, now))
            .and_then(|switch| self.take_switch(next, &switch).map(|()| switch));
        match switched {
            Ok(switch) => {
                self.report_switch(&switch, Some(from));
                self.mac_switch_state()
            }
            Err(e) => {
                tracing::warn!(from = from.name(), "MAC switch to {name:?} refused: {e}");
                let active = current.switcher.active().to_string();
                self.report(
                    0,
                    ModemEvent::MacSwitch(MacSwitched {
                        active: active.clone(),
                        previous: active,
                        reason: "refused",
                        until: current.switcher.until(),
                        from: Some(from.name()),
                        error: Some(e.clone()),
                    }),
                );
                Err(e)
            }
        }
    }

    /// Goes back to the default MAC when the running one's keep-alive has
    /// run out.
    pub(super) fn mac_switch_lapse(&mut self) {
        let now = self.clock.now();
        let Some(mut next) = self.mac_switcher.as_ref().map(|s| s.switcher.clone()) else {
            return;
        };
        let Some(switch) = next.lapse(now) else {
            return;
        };
        // The default runs even when the state cannot be kept: it is what
        // the node must fall back to.
        match self.switch_to(next, &switch, false) {
            Ok(()) => self.report_switch(&switch, None),
            Err(e) => tracing::error!("MAC switcher: {e}"),
        }
    }

    /// Runs the state kept in the data directory (what happens is logged
    /// and told).
    pub(super) fn restore_mac_switch(&mut self) {
        let Some(mut next) = self.mac_switcher.as_ref().map(|s| s.switcher.clone()) else {
            return;
        };
        let file = MacSwitchFile::in_dir(self.data_dir.path());
        let kept = match file.load(self.modem_id, next.names()) {
            Ok(Some(kept)) => kept,
            Ok(None) => return,
            Err(e) => {
                tracing::warn!("{e}; the default MAC runs");
                return;
            }
        };
        let now = self.clock.now();
        let restored = next.restore(kept.active(), kept.keep_alive_until, now);
        match restored.and_then(|switch| self.take_switch(next, &switch).map(|()| switch)) {
            Ok(switch) => self.report_switch(&switch, None),
            Err(e) => tracing::error!("{}: {e}; the default MAC runs", file.path().display()),
        }
    }

    /// Makes `next` (after `switch`) the switcher's state: kept on disk
    /// first, then the first link runs its MAC, built anew when another
    /// one runs. Errors: the MAC cannot be built or the state kept.
    fn take_switch(&mut self, next: Switcher, switch: &Switch) -> Result<(), String> {
        self.switch_to(next, switch, true)
    }

    /// As [`take_switch`](Self::take_switch); with `must_keep` false a
    /// state that cannot be kept is logged and the switch made anyway.
    fn switch_to(
        &mut self,
        next: Switcher,
        switch: &Switch,
        must_keep: bool,
    ) -> Result<(), String> {
        let Some(current) = self.mac_switcher.as_mut() else {
            return Ok(());
        };
        let config = current.macs.get(next.active()).cloned().unwrap_or_default();
        let now = self.clock.now();
        let built = if switch.changed() {
            Some(MacManager::new(&config, now).map_err(|e| e.to_string())?)
        } else {
            None
        };
        let state = KeptState {
            active: Some(next.active().to_string()),
            keep_alive_until: next.until(),
            modem_id: Some(self.modem_id),
            names: next.names().to_vec(),
        };
        let kept = MacSwitchFile::in_dir(self.data_dir.path())
            .save(&state)
            .map_err(|e| format!("the switch could not be kept: {e}"));
        match kept {
            Err(e) if must_keep => return Err(e),
            Err(e) => tracing::error!("MAC switcher: {e}; a restart may run the lapsed MAC until it sees the deadline passed"),
            Ok(()) => {}
        }
        current.switcher = next;
        if let Some(mac) = built {
            // The changes made to the MAC that ran before are dropped; at a
            // restore the kept changes are the restored MAC's own, and
            // `restore_mac_cycle` runs them next.
            if switch.reason != amac::SwitchReason::Restored {
                if let Err(e) = MacCycleFile::in_dir(self.data_dir.path()).remove() {
                    tracing::warn!("{e}");
                }
            }
            self.links[0].mac = mac;
            self.links[0].adaptive_rate = config.adaptive_rate();
            self.configured_mac = config;
        }
        Ok(())
    }

    /// Tells `switch` on the `mac` events and in the log; a switch to
    /// another MAC also tells the cycle it runs now (a `mac_cycle` event
    /// from `switch`, no update).
    fn report_switch(&self, switch: &Switch, from: Option<UpdateSource>) {
        tracing::info!(
            from = from.map(UpdateSource::name),
            reason = switch.reason.name(),
            until = switch.until,
            "MAC switcher: {} runs (was {})",
            switch.to,
            switch.from
        );
        self.report(
            0,
            ModemEvent::MacSwitch(MacSwitched {
                active: switch.to.clone(),
                previous: switch.from.clone(),
                reason: switch.reason.name(),
                until: switch.until,
                from: from.map(UpdateSource::name),
                error: None,
            }),
        );
        if switch.changed() {
            self.report(
                0,
                ModemEvent::MacCycle {
                    cycle: self.mac_cycle(),
                    update: None,
                    from: "switch",
                    error: None,
                },
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_keep_alive_must_be_a_positive_number_of_seconds() {
        assert_eq!(keep_alive_micros(None), Ok(None));
        assert_eq!(keep_alive_micros(Some(1.5)), Ok(Some(1_500_000)));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e18, 1e300] {
            assert!(keep_alive_micros(Some(bad)).is_err(), "{bad}");
        }
        assert!(keep_alive_micros(Some(1e300))
            .unwrap_err()
            .contains("more than a year"));
    }
}
