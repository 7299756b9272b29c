//! The core's links: starting their drivers, following their health
//! (supervised links are started again after a back-off), their byte
//! budgets, the slots of their medium access control and what their data
//! requests are filled with.

use std::path::Path;
use std::sync::Arc;

use amac::MacManager;
use modemdriver::{DataRequest, Driver, DriverEvent, DriverStatus, ModemTransmission};
use prost_reflect::ReflectMessage;
use protos::goby::apps::protobuf::GobydConfig;

use super::link::backoff::Backoff;
use super::link::budget::{Budget, BudgetFile};
use super::link::{self, Link};
use super::Core;
use crate::config;
use crate::error::DaemonError;
use crate::event::{DaemonEvent, ModemEvent, SharedUse};

/// Starts the driver named by the configuration (its settings checked as
/// [`validate`](crate::check::validate) does).
pub async fn start_driver(
    config: &protos::goby::acomms::protobuf::DriverConfig,
) -> Result<Driver, DaemonError> {
    Ok(modemdriver::built_in::start(config).await?)
}

/// Why a link's driver could not start, in words (the driver's own error
/// without the daemon's `driver:` before it: the link's words name it).
pub(crate) fn start_error(e: DaemonError) -> String {
    match e {
        DaemonError::Driver(e) => e.to_string(),
        other => other.to_string(),
    }
}

/// A Micro-Modem with application acks keeps its frame numbers in the data
/// directory (`micromodem.application_ack_state_file`, unless set), so
/// that after a restart acks are credited at once.
pub(crate) fn keep_application_acks_in(
    driver: &mut protos::goby::acomms::protobuf::DriverConfig,
    data_dir: &Path,
) {
    if let Some(mm) = driver.micromodem.as_mut().filter(|mm| {
        modemdriver::micromodem::application_ack::Mode::of(mm).on()
            && mm.application_ack_state_file.is_none()
    }) {
        let path = data_dir.join("micromodem-application-acks");
        mm.application_ack_state_file = Some(path.to_string_lossy().into_owned());
    }
}

/// The links of `config`, each on its start (`starts`, in the order of
/// the configuration's links: its driver or why it could not start, and
/// its configuration for restarts), their budgets restored from the data
/// directory `dir`; and where the budgets are kept. `several`: the
/// configuration has `link` sections (links are supervised). `now`:
/// microseconds since the epoch.
pub(crate) fn open(
    config: &GobydConfig,
    starts: Vec<super::LinkStart>,
    dir: &Path,
    now: i64,
    several: bool,
) -> Result<(Vec<Link>, Option<BudgetFile>), DaemonError> {
    let views = config::links::links(config);
    let budgeted = views.iter().any(|v| v.budget().is_some());
    let budget_file = budgeted.then(|| BudgetFile::in_dir(dir));
    let kept = match budget_file.as_ref().map(BudgetFile::load) {
        Some(Err(e)) => {
            tracing::error!(
                "link budgets: {e}; every budget is taken as spent until its next period"
            );
            None
        }
        Some(Ok(kept)) => Some(kept),
        None => Some(Default::default()),
    };
    let mut links = Vec::new();
    let restart_now = tokio::time::Instant::now();
    for (view, (started, driver_config)) in views.iter().zip(starts) {
        let (min, max) = view.restart();
        let mut budget = view
            .budget()
            .map(|(bytes, period)| Budget::new(bytes, period, now));
        if let Some(b) = &mut budget {
            match kept.as_ref() {
                Some(kept) => {
                    if let Some(k) = kept.get(&view.name) {
                        b.restore(k);
                    }
                }
                None => b.exhaust(),
            }
        }
        // Its kind's name until a driver has started (a link whose driver
        // fails at start is named by its kind all the same).
        let kind_name = driver_config
            .as_ref()
            .and_then(|c| modemdriver::built_in::of(c).ok())
            .map_or("", |k| k.about().short_name);
        let mut link = Link {
            name: view.name.clone(),
            driver: None,
            driver_name: kind_name,
            mac: MacManager::new(view.mac.expect("completed"), now)?,
            config: driver_config,
            specific_requests: Default::default(),
            health: link::Health::Up,
            supervised: several,
            backoff: Backoff::new(min, max),
            last_error: None,
            restarts: 0,
            budget,
            slot_types: Vec::new(),
            adaptive_rate: view.mac.is_some_and(|m| m.adaptive_rate()),
            rates: Default::default(),
        };
        match started {
            Ok(driver) => {
                link.driver_name = driver.name();
                link.driver = Some(driver);
            }
            Err(e) => {
                let wait = link.backoff.failed();
                tracing::error!(
                    link = view.name,
                    "link {}: the {} driver could not start: {e}; starting it again in {:.1} s",
                    view.name,
                    link.driver_name,
                    wait.as_secs_f64()
                );
                link.last_error = Some(e);
                link.health = link::Health::Down {
                    restart_at: restart_now + wait,
                };
            }
        }
        links.push(link);
    }
    Ok((links, budget_file))
}

impl Core {
    /// Answers a data request of link `i` with its frames filled
    /// ([`fill`](Self::fill)), after the network layer, when there is one,
    /// has put what it has to send in the outbox: the frames go from the
    /// queue to the driver here.
    pub(super) fn answer_data_request(&mut self, i: usize, request: DataRequest) {
        if let Some(network) = &mut self.network {
            network.data_request(&mut self.outbox, self.clock.now());
        }
        let mut filled = request.template().clone();
        self.fill(i, &mut filled);
        request.respond(filled);
    }

    /// Fills the frames of a data request of link `i`: the link states
    /// told to the queue first (which links are up, what their budgets
    /// have left), the request cut to the bytes its budget has left, and
    /// what it carries counted against the budget and kept on disk before
    /// the driver has it.
    fn fill(&mut self, i: usize, request: &mut ModemTransmission) {
        let now = self.clock.now();
        self.tell_link_states(now);
        let left = self.links[i].budget.as_mut().map(|b| b.left(now));
        // The frames' bytes, and their identities where they go beside.
        let bytes_of = |r: &ModemTransmission| -> usize {
            r.frame.iter().chain(&r.frame_identity).map(Vec::len).sum()
        };
        let before = bytes_of(request);
        if let Some(left) = left {
            let left = usize::try_from(left).unwrap_or(usize::MAX);
            let bytes = request.max_frame_bytes.map_or(usize::MAX, |b| b as usize);
            if left < bytes {
                request.max_frame_bytes = Some(left as u32);
                request.max_num_frames = Some(request.max_num_frames().min(1));
            } else {
                let frames = (left / bytes.max(1)).min(request.max_num_frames() as usize);
                request.max_num_frames = Some(frames as u32);
            }
        }
        let filled = if left == Some(0) {
            Ok(())
        } else {
            let only = self.links[i].slot_types.clone();
            self.outbox.data_request(request, i, &only)
        };
        if let Err(e) = filled {
            tracing::warn!("data request: {e}");
        }
        let after = bytes_of(request);
        let spent = after.saturating_sub(before);
        if let (Some(budget), true) = (self.links[i].budget.as_mut(), spent > 0) {
            budget.spend(spent as u64, now);
            self.save_budgets();
            self.report_link(i);
        }
    }

    /// Tells the queue which links are up and what their budgets have
    /// left (with `link` sections).
    pub(super) fn tell_link_states(&mut self, now: i64) {
        if !self.several {
            return;
        }
        let states: Vec<queue::LinkState> = self
            .links
            .iter_mut()
            .map(|l| queue::LinkState {
                up: l.is_up(),
                budget_left: l
                    .budget
                    .as_mut()
                    .map(|b| usize::try_from(b.left(now)).unwrap_or(usize::MAX)),
            })
            .collect();
        if let Some(links) = self.outbox.links_mut() {
            for (i, state) in states.into_iter().enumerate() {
                links.set_state(i, state);
            }
        }
    }

    /// Writes what each budgeted link spent to `DATA_DIR/link_budget`,
    /// durably.
    pub(super) fn save_budgets(&self) {
        let Some(file) = &self.budget_file else {
            return;
        };
        let kept = self
            .links
            .iter()
            .filter_map(|l| Some((l.name.as_str(), l.budget.as_ref()?.kept())));
        if let Err(e) = file.save(kept) {
            tracing::error!("link budgets: cannot write {}: {e}", file.path().display());
        }
    }

    /// Starts the budgets' new periods that are due, and tells.
    pub(super) fn roll_budgets(&mut self) {
        let now = self.clock.now();
        for i in 0..self.links.len() {
            let rolled = self.links[i].budget.as_mut().is_some_and(|b| b.roll(now));
            if rolled {
                tracing::info!(link = self.links[i].name, "link budget: a new period");
                self.save_budgets();
                self.report_link(i);
            }
        }
    }

    /// Follows link `i`'s health from its driver's events: a supervised
    /// link whose device is gone fails (and is started again); a link
    /// not supervised is away until its driver reconnects; one that shows
    /// life starts its back-off over.
    pub(super) fn link_health(&mut self, i: usize, event: &DriverEvent) {
        let link = &mut self.links[i];
        if Link::shows_life(event) {
            link.backoff.worked();
            if link.health == link::Health::Away {
                link.health = link::Health::Up;
                self.report_link(i);
            }
            return;
        }
        if let DriverEvent::Status(DriverStatus::Disconnected { reason }) = event {
            if link.supervised {
                self.link_failed(i, format!("disconnected: {reason}"));
            } else if link.health != link::Health::Away {
                link.health = link::Health::Away;
                link.last_error = Some(format!("disconnected: {reason}"));
                self.report_link(i);
            }
        }
    }

    /// Link `i`'s driver failed (`reason`): it is stopped, the messages
    /// it had in hand are queued again, and it is started again after its
    /// back-off; the other links run on.
    pub(super) fn link_failed(&mut self, i: usize, reason: String) {
        let link = &mut self.links[i];
        if let Some(driver) = link.driver.take() {
            tokio::spawn(async move {
                let _ = driver.stop().await;
            });
        }
        let wait = link.backoff.failed();
        link.health = link::Health::Down {
            restart_at: tokio::time::Instant::now() + wait,
        };
        tracing::warn!(
            link = link.name,
            "link {} is down ({reason}); its driver starts again in {:.1} s (failure {} in a row)",
            link.name,
            wait.as_secs_f64(),
            link.backoff.failures()
        );
        link.last_error = Some(reason);
        let n = self.outbox.transmitted(i, false);
        if n > 0 {
            tracing::info!("{n} messages queued again from the failed link");
        }
        self.report_link(i);
    }

    /// Starts again the drivers of the links that are due.
    pub(super) fn restart_due(&mut self) {
        let now = tokio::time::Instant::now();
        for i in 0..self.links.len() {
            let link::Health::Down { restart_at } = self.links[i].health else {
                continue;
            };
            if restart_at > now {
                continue;
            }
            let Some(config) = self.links[i].config.clone() else {
                // A caller's driver: nothing to start it from.
                self.links[i].health = link::Health::Away;
                self.report_link(i);
                continue;
            };
            self.links[i].health = link::Health::Restarting;
            tracing::info!(link = self.links[i].name, "starting the driver again");
            self.starts.spawn(async move {
                let started = start_driver(&config).await.map_err(start_error);
                (i, started)
            });
            self.report_link(i);
        }
    }

    /// A driver started again (or could not be).
    pub(super) fn restarted(&mut self, i: usize, started: Result<Driver, String>) {
        match started {
            Ok(driver) => {
                let link = &mut self.links[i];
                // What the old driver had under way will not end.
                if let Some(aloha) = link.mac.aloha() {
                    aloha.reset();
                }
                link.driver_name = driver.name();
                link.driver = Some(driver);
                link.health = link::Health::Up;
                link.restarts += 1;
                tracing::info!(
                    link = link.name,
                    "link {} is up again (restart {})",
                    link.name,
                    link.restarts
                );
                self.report_link(i);
            }
            Err(e) => {
                let kind = self.links[i].driver_name;
                self.link_failed(i, format!("the {kind} driver could not start: {e}"))
            }
        }
    }

    /// Sends link `i`'s status to the interfaces (and keeps it for the
    /// clients that subscribe later).
    pub(super) fn report_link(&self, i: usize) {
        let now = self.clock.now();
        let instant = tokio::time::Instant::now();
        let status = self.links[i].status(now, instant);
        self.link_status.send_modify(|all| {
            if let Some(s) = all.get_mut(i) {
                *s = status.clone();
            }
        });
        let _ = self.events.send(Arc::new(DaemonEvent::Link(status)));
    }

    /// Starts the slots due. Each transmission initiated gets a `unique_id`
    /// (the acks that answer it name it) and, in `time` and `slot_seconds`,
    /// the time left in its slot: the driver drops it rather than run it
    /// after its slot (e.g. when the modem was away).
    pub(super) fn mac_slots(&mut self) {
        for i in 0..self.links.len() {
            self.link_slots(i);
        }
    }

    /// Starts the slots due of link `i` (see [`mac_slots`](Self::mac_slots));
    /// a link that is down reports its slots and initiates nothing.
    pub(super) fn link_slots(&mut self, i: usize) {
        let now = self.clock.now();
        let events = self.links[i].mac.poll(now);
        // A driver whose device is away (and that reconnects by itself)
        // is given its slots as before: it decides what it can do.
        let up = self.links[i].driver.is_some();
        for event in events {
            let mut reported = ModemEvent::of_mac(&event);
            let amac::MacEvent::Slot(slot) = &event else {
                self.report(i, reported);
                continue;
            };
            // A driver-specific request takes this node's slot in place of
            // data.
            let specific = slot
                .initiate()
                .filter(|_| up)
                .and_then(|_| self.links[i].specific_requests.pop_front());
            // A shared slot is this node's when its data is urgent enough.
            let contended = self.contend(i, slot, up);
            let used = matches!(contended, Some(SharedUse::Used { .. }));
            let mine = slot.initiate().or(used.then_some(&slot.transmission));
            let initiated = match (mine.filter(|_| up), &specific) {
                (Some(transmission), None) => {
                    let mut transmission = transmission.clone();
                    self.next_transmission = self.next_transmission.wrapping_add(1);
                    transmission.unique_id = Some(self.next_transmission);
                    let opened = transmission
                        .time
                        .and_then(|t| i64::try_from(t).ok())
                        .unwrap_or(slot.position.start);
                    transmission.time = u64::try_from(opened).ok();
                    transmission.slot_seconds =
                        Some((slot.position.end - opened).max(0) as f64 / 1e6);
                    Some(transmission)
                }
                _ => None,
            };
            // Its rate chosen from the link (a slot with `adaptive_rate`),
            // as the slot start tells it.
            let initiated = initiated.map(|mut t| {
                self.adapt_rate(i, &mut t);
                t
            });
            if let ModemEvent::SlotStart {
                initiated: told,
                shared,
                ..
            } = &mut reported
            {
                *told = initiated.clone().map(Box::new);
                if contended.is_some() {
                    *shared = contended;
                }
            }
            self.report(i, reported);
            if let Some(request) = specific {
                tracing::info!(
                    slot = slot.position.index,
                    "this node's slot carries a driver-specific request ({})",
                    request.descriptor().full_name()
                );
                let outcome = self.links[i]
                    .driver
                    .as_ref()
                    .map(|d| d.initiate_specific(&request));
                if let Some(Err(e)) = outcome {
                    tracing::error!("cannot start a driver-specific request: {e}");
                }
            }
            if let Some(transmission) = initiated {
                self.links[i].slot_types = self.slot_types(&transmission);
                tracing::debug!(
                    unique_id = self.next_transmission,
                    slot = slot.position.index,
                    "initiating a transmission"
                );
                let outcome = self.links[i]
                    .driver
                    .as_ref()
                    .map(|d| d.initiate_transmission(transmission));
                if let Some(Err(e)) = outcome {
                    tracing::error!("cannot initiate a transmission: {e}");
                }
            }
        }
    }

    /// Pure ALOHA (`MAC_ALOHA`, [`amac::aloha`]): each link so run whose
    /// driver is up and whose own last transmission has ended sends at
    /// once when a message waits, its destination left to the queue.
    pub(super) fn aloha_transmissions(&mut self) {
        for i in 0..self.links.len() {
            let idle = self.links[i].mac.aloha().is_some_and(|a| !a.sending());
            if !idle || self.links[i].driver.is_none() {
                continue;
            }
            let has_data = self.most_urgent().is_some();
            let link = &mut self.links[i];
            let (Some(driver), Some(aloha)) = (link.driver.as_ref(), link.mac.aloha()) else {
                continue;
            };
            let unique_id = self.next_transmission.wrapping_add(1);
            let Some(transmission) = aloha.ready(has_data, unique_id, self.clock.now()) else {
                continue;
            };
            self.next_transmission = unique_id;
            link.slot_types = Vec::new();
            tracing::debug!(unique_id, "initiating a transmission (ALOHA)");
            if let Err(e) = driver.initiate_transmission(transmission) {
                tracing::error!("cannot initiate a transmission: {e}");
                aloha.reset();
            }
        }
    }

    /// What this node does with a shared slot it may contend for
    /// ([`amac::SlotAction::Contend`]) on link `i`: it uses it when the
    /// link is up and its most urgent queue has at least the slot's
    /// `min_priority` (then it backs off, [`amac::MacManager::shared_slot_used`]);
    /// `None` for any other slot.
    fn contend(&mut self, i: usize, slot: &amac::SlotEvent, up: bool) -> Option<SharedUse> {
        if slot.action != amac::SlotAction::Contend {
            return None;
        }
        let threshold = slot.transmission.shared.as_ref()?.min_priority();
        let priority = self.most_urgent();
        if up && priority.is_some_and(|p| p >= threshold) {
            let backoff = self.links[i].mac.shared_slot_used();
            return Some(SharedUse::Used { backoff });
        }
        Some(SharedUse::BelowThreshold { priority })
    }

    /// The DCCL ids of the types a scripted TDMA slot may carry (its
    /// `packet_type`s; empty: every type, as for a slot without them or
    /// with "any"). A name that is not loaded (refused by `--check`, but
    /// possible in a cycle changed at sea) is logged and carries nothing.
    fn slot_types(&self, slot: &ModemTransmission) -> Vec<u32> {
        if slot.packet_type.iter().any(|t| t == "any") {
            return Vec::new();
        }
        let ids: Vec<u32> = slot
            .packet_type
            .iter()
            .filter_map(|name| match self.codec.id_of(name) {
                Ok(id) => Some(id),
                Err(_) => {
                    tracing::warn!(
                        "slot {}: packet_type {name} is not a loaded DCCL type",
                        slot.slot_index()
                    );
                    None
                }
            })
            .collect();
        if ids.is_empty() && !slot.packet_type.is_empty() {
            // None of its types is loaded: it carries nothing (no type
            // has the largest id).
            return vec![u32::MAX];
        }
        ids
    }

    /// The priority of the most urgent queue holding messages (`None`:
    /// every queue is empty).
    fn most_urgent(&self) -> Option<f64> {
        let queue = self.outbox.queue();
        queue
            .configured()
            .iter()
            .filter(|name| queue.size(name).is_ok_and(|n| n > 0))
            .filter_map(|name| queue.priority(name).ok())
            .reduce(f64::max)
    }

    /// Stops the driver and starts it again from its configuration;
    /// messages of a transmission under way are queued again. When the
    /// driver cannot start again the daemon stops as for a driver that
    /// stopped (its messages stay in the journal).
    pub(super) async fn reset_driver(&mut self, i: usize) -> Result<(), String> {
        let Some(config) = self.links[i].config.clone() else {
            return Err(
                "the driver was started by the embedding program: it cannot be reset".into(),
            );
        };
        let Some(old) = self.links[i].driver.take() else {
            // Down: it is being started again already.
            return Ok(());
        };
        tracing::warn!("driver reset requested: stopping {}", old.name());
        if let Err(e) = old.stop().await {
            tracing::warn!("driver stop: {e}");
        }
        self.outbox.transmitted(i, false);
        let driver = match start_driver(&config).await {
            Ok(driver) => driver,
            Err(e) if self.links[i].supervised => {
                let e = e.to_string();
                tracing::error!("driver reset: {e}");
                self.link_failed(i, e.clone());
                return Err(e);
            }
            Err(e) => {
                // The stand-in that has stopped already: the daemon stops
                // as for a driver that stopped.
                self.links[i].driver = Some(Driver::spawn("stopped", |_| async {}));
                tracing::error!("driver reset: {e}");
                return Err(e.to_string());
            }
        };
        tracing::info!("driver {} started again", driver.name());
        self.links[i].driver_name = driver.name();
        self.links[i].driver = Some(driver);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::{
        micro_modem_config::ApplicationAcks, DriverConfig, MicroModemConfig,
    };

    /// The frame numbers are kept for every setting that sends application
    /// acks, `application_acks: FDP_ONLY` included (which gobyd leaves
    /// `use_application_acks` unset beside).
    #[test]
    fn application_ack_numbers_are_kept_with_any_setting_that_sends_them() {
        let kept = |mm: MicroModemConfig| {
            let mut driver = DriverConfig {
                micromodem: Some(mm),
                ..Default::default()
            };
            keep_application_acks_in(&mut driver, Path::new("/data"));
            driver.micromodem.unwrap().application_ack_state_file
        };
        let mode = |m: ApplicationAcks| MicroModemConfig {
            application_acks: Some(m as i32),
            ..Default::default()
        };
        let file = Some("/data/micromodem-application-acks".to_string());
        assert_eq!(kept(mode(ApplicationAcks::FdpOnly)), file);
        assert_eq!(kept(mode(ApplicationAcks::All)), file);
        assert_eq!(kept(mode(ApplicationAcks::None)), None);
        let flag = MicroModemConfig {
            use_application_acks: Some(true),
            ..Default::default()
        };
        assert_eq!(kept(flag), file);
    }
}
