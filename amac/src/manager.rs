//! The medium access control of one node: a deterministic state machine that
//! turns the current time into slot starts.

use protos::goby::acomms::protobuf::mac_config::MacRefTime;
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::{MacConfig, MacType, ModemTransmission};

use crate::aloha::Aloha;
use crate::clock::{seconds_to_micros, Micros, MICROS_PER_DAY};
use crate::discovery::{DiscoveryAction, DiscoveryNode, DiscoveryRule, DiscoverySettings};
use crate::error::AmacError;
use crate::schedule::{CycleLayout, Reference, SlotPosition};
use crate::shared::{SharedChoice, SharedSlots};

/// Modem id meaning "everyone"; a slot with this source is a quiet slot.
pub const BROADCAST_ID: i32 = 0;
/// Modem id meaning "to be filled in" (the destination of the first message queued).
pub const QUERY_DESTINATION_ID: i32 = -1;

/// What this node does in a slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlotAction {
    /// Start the slot's transmission now: hand
    /// [`SlotEvent::transmission`] to the modem driver.
    Initiate,
    /// Another node transmits: listen.
    Listen,
    /// The blank slot of auto-discovery: nobody known transmits.
    Blank,
    /// Auto-discovery with back-off: this node's slot, left quiet this time.
    BackOff,
    /// Auto-discovery: the cycle changed and the new one has not started yet.
    Wait,
    /// This node's slot, but it was over before [`MacManager::poll`] ran:
    /// nothing is initiated.
    Missed,
    /// A shared slot (slotted ALOHA, [`crate::shared`]) this node may
    /// initiate: [`SlotEvent::transmission`] carries this node as `src`.
    /// The caller initiates it only when its most urgent queue has at
    /// least the slot's `shared.min_priority`, and then tells
    /// [`MacManager::shared_slot_used`].
    Contend,
    /// A shared slot this node lets go by (its random back-off after
    /// using one).
    SharedBackOff,
}

/// The start of one slot.
#[derive(Debug, Clone, PartialEq)]
pub struct SlotEvent {
    /// Position of the slot: cycle number, index, start and end.
    pub position: SlotPosition,
    /// What this node does in it.
    pub action: SlotAction,
    /// The slot as a transmission: `src`, `dest`, `rate`, `type`,
    /// `slot_seconds`, `slot_index`, and `time` (when it is initiated,
    /// microseconds since the epoch).
    pub transmission: ModemTransmission,
}

impl SlotEvent {
    /// The transmission to initiate, if this node initiates the slot.
    pub fn initiate(&self) -> Option<&ModemTransmission> {
        (self.action == SlotAction::Initiate).then_some(&self.transmission)
    }
}

/// Something the medium access control reports.
#[derive(Debug, Clone, PartialEq)]
pub enum MacEvent {
    /// A slot started (boxed: a slot carries a whole transmission).
    Slot(Box<SlotEvent>),
    /// Auto-discovery: a node was heard for the first time and joins the cycle.
    Discovered {
        /// Its modem id.
        modem_id: i32,
        /// End of the slot in which it was heard.
        at: Micros,
    },
    /// Auto-discovery: a node was not heard for `expire_cycles` cycles and
    /// leaves the cycle.
    Expired {
        /// Its modem id.
        modem_id: i32,
        /// End of the slot after which it was dropped.
        at: Micros,
    },
}

impl MacEvent {
    /// The transmission to initiate, if this event asks for one.
    pub fn initiate(&self) -> Option<&ModemTransmission> {
        match self {
            MacEvent::Slot(slot) => slot.initiate(),
            _ => None,
        }
    }
}

/// A configured list of slots (fixed decentralized or polled).
#[derive(Debug, Clone)]
struct ListedCycle {
    slots: Vec<ModemTransmission>,
    layout: Option<CycleLayout>,
    next: Option<SlotPosition>,
    /// Back-off in the shared slots (fixed scheme).
    shared: SharedSlots,
    /// `max_backoff_slots` of the last shared slot contended for.
    last_max_backoff: u32,
}

/// Auto-discovery state.
#[derive(Debug, Clone)]
struct AutoCycle {
    node: DiscoveryNode,
    slot_len: Micros,
    rate: i32,
    /// Time of slot 0 of the present numbering.
    origin: Micros,
    /// Next slot to start.
    next_k: i64,
}

#[derive(Debug, Clone)]
enum Scheme {
    None,
    Aloha(Aloha),
    Fixed(ListedCycle),
    Polled(ListedCycle),
    Auto(AutoCycle),
}

/// The medium access control of one node.
#[derive(Debug, Clone)]
pub struct MacManager {
    modem_id: i32,
    reference: Reference,
    guard: Micros,
    start_cycle_in_middle: bool,
    scheme: Scheme,
    /// Start of the last slot reported.
    last_start: Option<Micros>,
    /// Whether the cycle runs (a `MACUpdate` may stop it).
    running: bool,
}

fn check_seconds(field: String, value: f64, minimum_exclusive: f64) -> Result<Micros, AmacError> {
    if !value.is_finite() || value <= minimum_exclusive {
        return Err(AmacError::config_field(
            field,
            format!("must be a finite number of seconds above {minimum_exclusive}, not {value}"),
        ));
    }
    if value > MAX_SLOT_SECONDS {
        return Err(AmacError::config_field(
            field,
            format!(
                "{value} s is longer than a day ({MAX_SLOT_SECONDS} s): a slot is seconds to \
                 minutes (a slot of a MACUpdate sent over the link is at most 3600 s)"
            ),
        ));
    }
    Ok(seconds_to_micros(value))
}

/// The longest slot (seconds): a day. Longer is a mistake, and a cycle of
/// such slots would overflow the microsecond clock.
pub const MAX_SLOT_SECONDS: f64 = 86_400.0;

impl MacManager {
    /// Starts the medium access control described by `config` at time `now`.
    ///
    /// The first slot is the first one starting at or after `now` (with
    /// `start_cycle_in_middle`, or for auto-discovery), or else the first
    /// start of a whole cycle.
    pub fn new(config: &MacConfig, now: Micros) -> Result<Self, AmacError> {
        let guard_seconds = config.guard_seconds();
        if !guard_seconds.is_finite() || guard_seconds < 0.0 {
            return Err(AmacError::config_field(
                "guard_seconds",
                format!("must be a finite number of seconds, 0 or more, not {guard_seconds}"),
            ));
        }
        let guard = seconds_to_micros(guard_seconds);
        let reference = match config.ref_time_type() {
            MacRefTime::ReferenceStartOfDay => Reference::StartOfUtcDay,
            MacRefTime::ReferenceFixed => match config.fixed_ref_time {
                Some(seconds) => Reference::Fixed(i64::from(seconds) * 1_000_000),
                None => {
                    return Err(AmacError::config_field(
                        "fixed_ref_time",
                        "must be set when ref_time_type is REFERENCE_FIXED",
                    ))
                }
            },
        };
        let modem_id = config.modem_id.unwrap_or(BROADCAST_ID);
        let kind = config.r#type();
        if matches!(
            kind,
            MacType::MacFixedDecentralized | MacType::MacAutoDecentralized | MacType::MacAloha
        ) && modem_id < 1
        {
            return Err(AmacError::config_field(
                "modem_id",
                format!(
                    "must be 1 or more for {}, not {modem_id}",
                    kind.as_str_name()
                ),
            ));
        }
        let mut manager = Self {
            modem_id,
            reference,
            guard,
            start_cycle_in_middle: config.start_cycle_in_middle(),
            scheme: Scheme::None,
            last_start: None,
            running: true,
        };
        manager.scheme = match kind {
            MacType::MacNone => Scheme::None,
            MacType::MacAloha => {
                if !config.slot.is_empty() {
                    return Err(AmacError::config_field(
                        "slot[0]",
                        "MAC_ALOHA has no slots (a node sends as soon as a message waits): leave \
                         slot out, or share slots with MAC_FIXED_DECENTRALIZED and shared { }",
                    ));
                }
                // The ack of a packet that asks for one is awaited for at
                // most slot_seconds.
                let ack_wait = config.slot_seconds();
                if !(ack_wait.is_finite() && ack_wait > 0.0) {
                    return Err(AmacError::config_field(
                        "slot_seconds",
                        format!(
                            "{ack_wait} is not a time in seconds (MAC_ALOHA awaits an ack this \
                             long at most)"
                        ),
                    ));
                }
                Scheme::Aloha(Aloha::new(
                    modem_id,
                    config.rate(),
                    (ack_wait * 1e6) as Micros,
                ))
            }
            MacType::MacFixedDecentralized | MacType::MacPolled => {
                let mut cycle = ListedCycle {
                    slots: Vec::new(),
                    layout: None,
                    next: None,
                    shared: SharedSlots::new(modem_id),
                    last_max_backoff: 0,
                };
                manager.check_slots(&config.slot, kind == MacType::MacPolled)?;
                cycle.slots = config.slot.clone();
                if kind == MacType::MacPolled {
                    Scheme::Polled(cycle)
                } else {
                    Scheme::Fixed(cycle)
                }
            }
            MacType::MacAutoDecentralized => {
                let slot_len = check_seconds("slot_seconds".into(), config.slot_seconds(), 0.0)?;
                if guard >= slot_len {
                    return Err(AmacError::config_field(
                        "guard_seconds",
                        "must be shorter than slot_seconds",
                    ));
                }
                if config.coolness() < 1 {
                    return Err(AmacError::config_field("coolness", "must be 1 or more"));
                }
                let node = DiscoveryNode::new(DiscoverySettings {
                    modem_id,
                    rule: DiscoveryRule::from_proto(config.auto_rule()),
                    coolness: config.coolness(),
                    expire_cycles: config.expire_cycles(),
                });
                let (origin, _) = reference.period_at(now);
                let next_k = (now - origin + slot_len - 1).div_euclid(slot_len);
                Scheme::Auto(AutoCycle {
                    node,
                    slot_len,
                    rate: config.rate(),
                    origin,
                    next_k,
                })
            }
        };
        manager.restart_listed(now);
        Ok(manager)
    }

    fn check_slots(&self, slots: &[ModemTransmission], polled: bool) -> Result<(), AmacError> {
        for (i, slot) in slots.iter().enumerate() {
            // (-1, the default, is a slot no node initiates.)
            if slot.src() < -1 {
                return Err(AmacError::config_field(
                    format!("slot[{i}].src"),
                    format!("{} is not a modem id (0 or more)", slot.src()),
                ));
            }
            if slot.dest() < -1 {
                return Err(AmacError::config_field(
                    format!("slot[{i}].dest"),
                    format!(
                        "{} is not a destination: a modem id, 0 for broadcast or -1 for the \
                         queue's choice",
                        slot.dest()
                    ),
                ));
            }
            if let Some(shared) = &slot.shared {
                if polled {
                    return Err(AmacError::config_field(
                        format!("slot[{i}].shared"),
                        "a shared slot (slotted ALOHA) needs MAC_FIXED_DECENTRALIZED: with MAC_POLLED the master initiates every slot",
                    ));
                }
                match shared.min_priority {
                    Some(p) if p.is_finite() => {}
                    Some(p) => {
                        return Err(AmacError::config_field(
                            format!("slot[{i}].shared.min_priority"),
                            format!("must be a finite priority, not {p}"),
                        ))
                    }
                    None => {
                        return Err(AmacError::config_field(
                            format!("slot[{i}].shared.min_priority"),
                            "a shared slot needs a priority threshold: the priority a node's most urgent queue must reach to use it",
                        ))
                    }
                }
            }
            let length =
                check_seconds(format!("slot[{i}].slot_seconds"), slot.slot_seconds(), 0.0)?;
            if self.guard >= length {
                return Err(AmacError::config_field(
                    "guard_seconds",
                    format!(
                        "must be shorter than slot[{i}].slot_seconds ({})",
                        slot.slot_seconds()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// This node's modem id (0 when not configured).
    pub fn modem_id(&self) -> i32 {
        self.modem_id
    }

    /// Name of the scheme, as in the configuration.
    pub fn scheme_name(&self) -> &'static str {
        match self.scheme {
            Scheme::None => "MAC_NONE",
            Scheme::Aloha(_) => "MAC_ALOHA",
            Scheme::Fixed(_) => "MAC_FIXED_DECENTRALIZED",
            Scheme::Polled(_) => "MAC_POLLED",
            Scheme::Auto(_) => "MAC_AUTO_DECENTRALIZED",
        }
    }

    /// Recomputes the next slot of a listed cycle after a change.
    fn restart_listed(&mut self, now: Micros) {
        let from = match self.last_start {
            Some(last) => now.max(last + 1),
            None => now,
        };
        let in_middle = self.start_cycle_in_middle;
        let reference = self.reference;
        if let Scheme::Fixed(cycle) | Scheme::Polled(cycle) = &mut self.scheme {
            let durations = cycle
                .slots
                .iter()
                .map(|s| seconds_to_micros(s.slot_seconds()))
                .collect();
            cycle.layout = CycleLayout::new(durations);
            cycle.next = cycle.layout.as_ref().map(|layout| {
                if in_middle {
                    layout.slot_starting_at_or_after(reference, from)
                } else {
                    layout.cycle_starting_at_or_after(reference, from)
                }
            });
        }
    }

    /// The slots of the present cycle as this node sees it. For
    /// auto-discovery: the known nodes and the blank (source 0) of the cycle
    /// holding the next slot.
    pub fn cycle(&self) -> Vec<ModemTransmission> {
        match &self.scheme {
            Scheme::None | Scheme::Aloha(_) => Vec::new(),
            Scheme::Fixed(c) | Scheme::Polled(c) => c.slots.clone(),
            Scheme::Auto(a) => a
                .node
                .cycle_at(a.next_k)
                .into_iter()
                .enumerate()
                .map(|(i, owner)| auto_transmission(a, owner.unwrap_or(BROADCAST_ID), i, None))
                .collect(),
        }
    }

    /// Auto-discovery: the modem ids this node knows (its own included), in
    /// cycle order. Empty for the other schemes.
    pub fn known_nodes(&self) -> Vec<i32> {
        match &self.scheme {
            Scheme::Auto(a) => a.node.known().to_vec(),
            _ => Vec::new(),
        }
    }

    /// Pure ALOHA (`MAC_ALOHA`): the node's state, which the daemon
    /// drives (no slots); `None` for the other schemes.
    pub fn aloha(&mut self) -> Option<&mut Aloha> {
        match &mut self.scheme {
            Scheme::Aloha(a) => Some(a),
            _ => None,
        }
    }

    /// Auto-discovery: the node's state.
    pub fn discovery_node(&self) -> Option<&DiscoveryNode> {
        match &self.scheme {
            Scheme::Auto(a) => Some(&a.node),
            _ => None,
        }
    }

    /// Fixed and polled schemes: the slot holding the instant `t` and its
    /// configuration, from the reference alone (no state involved).
    pub fn slot_at(&self, t: Micros) -> Option<(SlotPosition, &ModemTransmission)> {
        match &self.scheme {
            Scheme::Fixed(c) | Scheme::Polled(c) => {
                let position = c.layout.as_ref()?.slot_at(self.reference, t);
                Some((position, &c.slots[position.index]))
            }
            _ => None,
        }
    }

    /// When [`MacManager::poll`] next has something to report: the start of
    /// the next slot plus the guard time. `None` when no slot is configured.
    /// For `MAC_ALOHA`: when a pause after a failed transmission ends.
    pub fn next_event_time(&self) -> Option<Micros> {
        if let Scheme::Aloha(a) = &self.scheme {
            return a.paused_until();
        }
        if !self.running {
            return None;
        }
        self.next_slot_start().map(|start| start + self.guard)
    }

    fn next_slot_start(&self) -> Option<Micros> {
        match &self.scheme {
            Scheme::None | Scheme::Aloha(_) => None,
            Scheme::Fixed(c) | Scheme::Polled(c) => c.next.map(|p| p.start),
            Scheme::Auto(a) => {
                let start = a.next_k * a.slot_len;
                if self.reference == Reference::StartOfUtcDay && start >= MICROS_PER_DAY {
                    Some(a.origin + MICROS_PER_DAY)
                } else {
                    Some(a.origin + start)
                }
            }
        }
    }

    /// Starts every slot due by `now` (slot start plus guard time at or
    /// before `now`), in order, and reports them. A slot of this node that
    /// is already over is reported as [`SlotAction::Missed`].
    pub fn poll(&mut self, now: Micros) -> Vec<MacEvent> {
        if let Scheme::Aloha(a) = &mut self.scheme {
            a.resume(now);
        }
        let mut events = Vec::new();
        if !self.running {
            return events;
        }
        while let Some(start) = self.next_slot_start() {
            if start + self.guard > now {
                break;
            }
            self.start_next_slot(now, &mut events);
        }
        events
    }

    fn start_next_slot(&mut self, now: Micros, events: &mut Vec<MacEvent>) {
        let guard = self.guard;
        let modem_id = self.modem_id;
        let reference = self.reference;
        let start = match &mut self.scheme {
            Scheme::None | Scheme::Aloha(_) => return,
            Scheme::Fixed(c) => start_listed(c, false, modem_id, reference, guard, now, events),
            Scheme::Polled(c) => start_listed(c, true, modem_id, reference, guard, now, events),
            Scheme::Auto(a) => start_auto(a, modem_id, reference, guard, now, events),
        };
        self.last_start = start;
    }

    /// Auto-discovery: a transmission from modem `src` was received. It counts
    /// in the slot under way; a node heard for the first time joins the cycle
    /// at the end of that slot. Ignored by the other schemes.
    pub fn handle_received(&mut self, src: i32) {
        if let Scheme::Auto(a) = &mut self.scheme {
            a.node.heard(src);
        }
    }

    /// Fixed and polled schemes: replaces the cycle. The next slot is the
    /// next one of the new cycle (`start_cycle_in_middle`) or the start of
    /// the next whole cycle.
    pub fn set_slots(
        &mut self,
        slots: Vec<ModemTransmission>,
        now: Micros,
    ) -> Result<(), AmacError> {
        self.check_slots(&slots, matches!(self.scheme, Scheme::Polled(_)))?;
        match &mut self.scheme {
            Scheme::Fixed(c) | Scheme::Polled(c) => c.slots = slots,
            _ => {
                return Err(AmacError::WrongScheme {
                    operation: "changing the slot list",
                    scheme: self.scheme_name(),
                })
            }
        }
        self.restart_listed(now);
        Ok(())
    }

    /// Fixed and polled schemes: appends a slot to the cycle (see
    /// [`MacManager::set_slots`] for when the new cycle starts).
    pub fn add_slot(&mut self, slot: ModemTransmission, now: Micros) -> Result<(), AmacError> {
        let mut slots = self.cycle_if_listed()?;
        slots.push(slot);
        self.set_slots(slots, now)
    }

    /// Fixed and polled schemes: removes the slot at `index` and returns it.
    pub fn remove_slot(
        &mut self,
        index: usize,
        now: Micros,
    ) -> Result<ModemTransmission, AmacError> {
        let mut slots = self.cycle_if_listed()?;
        if index >= slots.len() {
            return Err(AmacError::config_field(
                format!("slot[{index}]"),
                format!("no such slot: the cycle has {}", slots.len()),
            ));
        }
        let removed = slots.remove(index);
        self.set_slots(slots, now)?;
        Ok(removed)
    }

    /// This node initiated the shared slot it was told to contend for
    /// ([`SlotAction::Contend`]): it lets a random number of shared slots
    /// go by (0 to the slot's `max_backoff_slots`) before it contends
    /// again. Returns the draw; 0 for a scheme without shared slots.
    pub fn shared_slot_used(&mut self) -> u32 {
        match &mut self.scheme {
            Scheme::Fixed(c) => {
                let max = c.last_max_backoff;
                c.shared.used(max)
            }
            _ => 0,
        }
    }

    /// Whether the cycle runs: false after a `MACUpdate` stopped it
    /// (`cycle_state: STOPPED`, or an update that emptied the cycle) and
    /// until one starts it again.
    pub fn running(&self) -> bool {
        self.running
    }

    /// Starts (`true`) or stops the cycle, as an update's `cycle_state`
    /// does; a cycle started again continues from the next slot after
    /// `now` (see [`MacManager::set_slots`]).
    pub fn set_running(&mut self, running: bool, now: Micros) {
        if running && !self.running {
            self.restart_listed(now);
        }
        self.running = running;
    }

    /// Applies a `MACUpdate` (see [`crate::update`]) as pAcommsHandler
    /// does: ignored unless `dest` is this node; the cycle is edited, then
    /// started or stopped by `cycle_state` when set (an emptied cycle
    /// stops). The next slot is found as after [`MacManager::set_slots`].
    ///
    /// Errors, the cycle unchanged: [`AmacError::NotForThisNode`], an index
    /// outside the cycle or a pop of an empty one
    /// ([`AmacError::InvalidField`] of `goby.acomms.protobuf.MACUpdate`),
    /// a slot this node cannot run (of `MACConfig`, as for the
    /// configuration), a scheme without a slot list
    /// ([`AmacError::WrongScheme`]).
    pub fn apply_update(
        &mut self,
        update: &protos::goby::acomms::protobuf::MacUpdate,
        now: Micros,
    ) -> Result<crate::UpdateOutcome, AmacError> {
        crate::update::check_dest(update, self.modem_id)?;
        let before = self.cycle_if_listed()?;
        let slots = crate::update::edit_cycle(&before, update)?;
        let running = crate::update::running_after(update, self.running, slots.len());
        self.set_slots(slots.clone(), now)?;
        self.running = running;
        Ok(crate::UpdateOutcome {
            update_type: crate::update::update_type(update)?,
            cycle: slots,
            running,
        })
    }

    fn cycle_if_listed(&self) -> Result<Vec<ModemTransmission>, AmacError> {
        match &self.scheme {
            Scheme::Fixed(c) | Scheme::Polled(c) => Ok(c.slots.clone()),
            _ => Err(AmacError::WrongScheme {
                operation: "changing the slot list",
                scheme: self.scheme_name(),
            }),
        }
    }
}

/// Starts the next slot of a listed cycle; returns its start.
fn start_listed(
    c: &mut ListedCycle,
    polled: bool,
    modem_id: i32,
    reference: Reference,
    guard: Micros,
    now: Micros,
    events: &mut Vec<MacEvent>,
) -> Option<Micros> {
    let position = c.next?;
    let layout = c.layout.as_ref()?;
    c.next = Some(layout.slot_at(reference, position.end));
    let mut transmission = c.slots[position.index].clone();
    transmission.time = u64::try_from(position.start + guard).ok();
    transmission.slot_index = Some(position.index as i32);
    if let Some(shared) = transmission.shared.filter(|_| !polled) {
        transmission.src = Some(modem_id);
        let action = match (c.shared.next_slot(), position.end <= now) {
            (SharedChoice::BackOff { .. }, _) => SlotAction::SharedBackOff,
            (SharedChoice::Contend, true) => SlotAction::Missed,
            (SharedChoice::Contend, false) => {
                c.last_max_backoff = shared.max_backoff_slots();
                SlotAction::Contend
            }
        };
        events.push(MacEvent::Slot(Box::new(SlotEvent {
            position,
            action,
            transmission,
        })));
        return Some(position.start);
    }
    let ours = if polled {
        transmission.src() != BROADCAST_ID
    } else {
        transmission.src() == modem_id
    };
    let action = match (ours, position.end <= now) {
        (true, false) => SlotAction::Initiate,
        (true, true) => SlotAction::Missed,
        (false, _) if transmission.src() == BROADCAST_ID => SlotAction::Blank,
        (false, _) => SlotAction::Listen,
    };
    events.push(MacEvent::Slot(Box::new(SlotEvent {
        position,
        action,
        transmission,
    })));
    Some(position.start)
}

/// End of auto-discovery slot `k` of the present numbering.
fn auto_slot_end(a: &AutoCycle, reference: Reference, k: i64) -> Micros {
    let end = a.origin + (k + 1) * a.slot_len;
    match reference {
        Reference::StartOfUtcDay => end.min(a.origin + MICROS_PER_DAY),
        Reference::Fixed(_) => end,
    }
}

/// Ends the auto-discovery slot under way, reporting what it taught.
fn end_auto_slot(a: &mut AutoCycle, reference: Reference, events: &mut Vec<MacEvent>) {
    let Some((k, _)) = a.node.current() else {
        return;
    };
    let at = auto_slot_end(a, reference, k);
    let outcome = a.node.end_slot();
    for modem_id in outcome.discovered {
        events.push(MacEvent::Discovered { modem_id, at });
    }
    for modem_id in outcome.expired {
        events.push(MacEvent::Expired { modem_id, at });
    }
}

/// Starts the next auto-discovery slot; returns its start.
fn start_auto(
    a: &mut AutoCycle,
    modem_id: i32,
    reference: Reference,
    guard: Micros,
    now: Micros,
    events: &mut Vec<MacEvent>,
) -> Option<Micros> {
    end_auto_slot(a, reference, events);
    if reference == Reference::StartOfUtcDay && a.next_k * a.slot_len >= MICROS_PER_DAY {
        // A new UTC day: the count of slots and cycles restarts at midnight.
        a.node.shift_slot_numbers(a.next_k);
        a.origin += MICROS_PER_DAY;
        a.next_k = 0;
    }
    let k = a.next_k;
    let start = a.origin + k * a.slot_len;
    let end = auto_slot_end(a, reference, k);
    let action = a.node.begin_slot(k);
    let len = a.node.cycle_len();
    let position = SlotPosition {
        cycle_number: k.div_euclid(len),
        index: k.rem_euclid(len) as usize,
        start,
        end,
    };
    let (owner, slot_action) = match action {
        DiscoveryAction::Transmit if end <= now => (modem_id, SlotAction::Missed),
        DiscoveryAction::Transmit => (modem_id, SlotAction::Initiate),
        DiscoveryAction::BackOff => (modem_id, SlotAction::BackOff),
        DiscoveryAction::Listen(id) => (id, SlotAction::Listen),
        DiscoveryAction::Blank => (BROADCAST_ID, SlotAction::Blank),
        DiscoveryAction::Wait => (BROADCAST_ID, SlotAction::Wait),
    };
    a.next_k += 1;
    let transmission = auto_transmission(a, owner, position.index, Some(start + guard));
    events.push(MacEvent::Slot(Box::new(SlotEvent {
        position,
        action: slot_action,
        transmission,
    })));
    Some(start)
}

/// An auto-discovery slot as a transmission.
fn auto_transmission(
    a: &AutoCycle,
    src: i32,
    index: usize,
    time: Option<Micros>,
) -> ModemTransmission {
    let mut t = ModemTransmission {
        src: Some(src),
        dest: Some(QUERY_DESTINATION_ID),
        rate: Some(a.rate),
        slot_seconds: Some(a.slot_len as f64 / 1e6),
        slot_index: Some(index as i32),
        time: time.and_then(|t| u64::try_from(t).ok()),
        ..Default::default()
    };
    t.set_type(TransmissionType::Data);
    t
}
