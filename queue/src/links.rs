//! Which link may carry a message now, when one node has several links
//! (an acoustic modem and Iridium, say) over one queue.
//!
//! Each link (a driver and its medium access) asks the queue for data *for
//! itself* ([`QueueManager::handle_modem_data_request`]); the queue offers
//! it only the messages its rules let that link carry at that moment. A
//! type's rule ([`LinkRule`]) lists the links it may use and a policy:
//!
//! - [`LinkPolicy::PriorityTimeout`]: the first link listed carries it; the
//!   next one may too once `timeout` has passed since the message was
//!   queued without its being acknowledged (or sent, for a type without
//!   ack), the one after that another `timeout` later, and so on. A link
//!   that is down, or whose budget has not the bytes of the message left
//!   (with its identity trailer, when frames carry one: a type of several
//!   links never goes without it), is skipped at once: the next link takes
//!   its turn.
//! - [`LinkPolicy::CheapestFirst`]: the same, the links taken in the order
//!   of their `cost` (lowest first; equal costs in the order listed).
//! - [`LinkPolicy::FloodAll`]: every listed link that is up and within its
//!   budget carries it at once.
//!
//! A type without a rule follows the default rule: every link, the first
//! configured preferred, [`LinkPolicy::PriorityTimeout`] with
//! [`DEFAULT_TIMEOUT_SECONDS`] (unless [`Links::set_default_rule`] gives
//! another).
//!
//! The decision is a pure function of the message's queuing time, its
//! size, the links' states ([`LinkState`], told by the caller) and the time
//! passed in: no clock is read here, so every policy runs in virtual time.
//! An ack on any link removes the message from the queue, and so from
//! every link. A message that may travel over several links is marked
//! `resent` in every sending ([`crate::identity`]): its copies may reach
//! the receiver in any order, and the receiver suppresses each copy after
//! the first it records.
//!
//! [`QueueManager::handle_modem_data_request`]: crate::QueueManager::handle_modem_data_request

use std::collections::HashMap;

use crate::clock::{seconds_to_micros, Micros};

/// Most links one queue serves.
pub const MAX_LINKS: usize = 8;

/// Timeout of the default rule (and of a rule that gives none), seconds.
pub const DEFAULT_TIMEOUT_SECONDS: f64 = 120.0;

/// A link's place in the node's configuration (0 first).
pub type LinkIndex = usize;

/// How the links of a rule share a type's messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LinkPolicy {
    /// The first link listed, the next after a timeout without an ack (at
    /// once when the first is down or over its budget).
    #[default]
    PriorityTimeout,
    /// Every link listed at once.
    FloodAll,
    /// The lowest `cost` first, the next after a timeout.
    CheapestFirst,
}

/// A link as the policies know it.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkSpec {
    /// Its name (for errors and status).
    pub name: String,
    /// What a message over it costs, in the operator's units (only the
    /// order matters, for [`LinkPolicy::CheapestFirst`]).
    pub cost: f64,
    /// The largest frame its driver sends, bytes, when it has a limit of
    /// its own (Iridium SBD): a larger message is never its to carry, and
    /// the rules pass it on at once.
    pub largest_frame: Option<usize>,
}

/// Which links a type may use, and how.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkRule {
    /// The links, in the order of preference written (indices into the
    /// node's links, each at most once).
    pub links: Vec<LinkIndex>,
    /// How they share the messages.
    pub policy: LinkPolicy,
    /// Time a message waits for an ack on one link before the next may
    /// carry it, microseconds.
    pub timeout: Micros,
}

impl LinkRule {
    /// A rule over `links` with `policy` and a timeout of `timeout_seconds`.
    pub fn new(links: Vec<LinkIndex>, policy: LinkPolicy, timeout_seconds: f64) -> Self {
        LinkRule {
            links,
            policy,
            timeout: seconds_to_micros(timeout_seconds),
        }
    }
}

/// What is known of a link now, as the caller tells it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkState {
    /// Its driver runs (not failed, not restarting).
    pub up: bool,
    /// Bytes it may still send in its budget's period (`None`: no budget).
    pub budget_left: Option<usize>,
}

impl Default for LinkState {
    fn default() -> Self {
        LinkState {
            up: true,
            budget_left: None,
        }
    }
}

/// Why a set of links or a rule was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct LinksError(pub String);

/// A rule with its links in the order they are tried.
#[derive(Debug, Clone, PartialEq)]
struct Resolved {
    order: Vec<LinkIndex>,
    policy: LinkPolicy,
    timeout: Micros,
}

/// The links of a node, their states, and the rules of its types.
#[derive(Debug, Clone)]
pub struct Links {
    specs: Vec<LinkSpec>,
    states: Vec<LinkState>,
    rules: HashMap<u32, Resolved>,
    default: Resolved,
}

impl Links {
    /// The links `specs` (1 to [`MAX_LINKS`]), all up with no budget, and
    /// the default rule (every link in order, priority with
    /// [`DEFAULT_TIMEOUT_SECONDS`]).
    pub fn new(specs: Vec<LinkSpec>) -> Result<Self, LinksError> {
        if specs.is_empty() || specs.len() > MAX_LINKS {
            return Err(LinksError(format!(
                "{} links: a node has 1 to {MAX_LINKS}",
                specs.len()
            )));
        }
        let default = Resolved {
            order: (0..specs.len()).collect(),
            policy: LinkPolicy::PriorityTimeout,
            timeout: seconds_to_micros(DEFAULT_TIMEOUT_SECONDS),
        };
        Ok(Links {
            states: vec![LinkState::default(); specs.len()],
            specs,
            rules: HashMap::new(),
            default,
        })
    }

    /// How many links there are.
    pub fn len(&self) -> usize {
        self.specs.len()
    }

    /// Always false: a set of links has one at least.
    pub fn is_empty(&self) -> bool {
        self.specs.is_empty()
    }

    /// The links as given.
    pub fn specs(&self) -> &[LinkSpec] {
        &self.specs
    }

    /// The rule of the types that have none of their own.
    pub fn set_default_rule(&mut self, rule: LinkRule) -> Result<(), LinksError> {
        self.default = self.resolve(rule)?;
        Ok(())
    }

    /// The rule of the type of DCCL id `dccl_id`.
    pub fn set_rule(&mut self, dccl_id: u32, rule: LinkRule) -> Result<(), LinksError> {
        let resolved = self.resolve(rule)?;
        self.rules.insert(dccl_id, resolved);
        Ok(())
    }

    fn resolve(&self, rule: LinkRule) -> Result<Resolved, LinksError> {
        if rule.links.is_empty() {
            return Err(LinksError("a rule names one link at least".into()));
        }
        let mut seen = [false; MAX_LINKS];
        for &l in &rule.links {
            if l >= self.specs.len() {
                return Err(LinksError(format!(
                    "link {l} does not exist (there are {})",
                    self.specs.len()
                )));
            }
            if std::mem::replace(&mut seen[l], true) {
                return Err(LinksError(format!(
                    "link {:?} is named twice",
                    self.specs[l].name
                )));
            }
        }
        if rule.timeout < 0 {
            return Err(LinksError("the timeout is negative".into()));
        }
        let mut order = rule.links;
        if rule.policy == LinkPolicy::CheapestFirst {
            // Stable: equal costs keep the order written.
            order.sort_by(|a, b| self.specs[*a].cost.total_cmp(&self.specs[*b].cost));
        }
        Ok(Resolved {
            order,
            policy: rule.policy,
            timeout: rule.timeout,
        })
    }

    /// Tells the state of `link` (ignored for a link that does not exist).
    pub fn set_state(&mut self, link: LinkIndex, state: LinkState) {
        if let Some(s) = self.states.get_mut(link) {
            *s = state;
        }
    }

    /// The state of `link` as last told.
    pub fn state(&self, link: LinkIndex) -> LinkState {
        self.states.get(link).copied().unwrap_or(LinkState {
            up: false,
            budget_left: Some(0),
        })
    }

    fn rule(&self, dccl_id: u32) -> &Resolved {
        self.rules.get(&dccl_id).unwrap_or(&self.default)
    }

    /// The links a type may use, in the order they are tried.
    pub fn order(&self, dccl_id: u32) -> &[LinkIndex] {
        &self.rule(dccl_id).order
    }

    /// The policy of a type.
    pub fn policy(&self, dccl_id: u32) -> LinkPolicy {
        self.rule(dccl_id).policy
    }

    /// Whether a type may travel over more than one link (its sendings are
    /// then all marked `resent`: see the [module](self)).
    pub fn several(&self, dccl_id: u32) -> bool {
        self.rule(dccl_id).order.len() > 1
    }

    /// Whether `link` is up, has `len` bytes left in its budget and
    /// sends frames of `len` bytes.
    pub fn available(&self, link: LinkIndex, len: usize) -> bool {
        let s = self.state(link);
        s.up && s.budget_left.is_none_or(|left| left >= len)
            && self.specs[link].largest_frame.is_none_or(|max| len <= max)
    }

    /// From when `link` may carry a message of type `dccl_id` of `len`
    /// bytes queued at `queued_at`, as the links stand now: `None` when it
    /// may not (not one of the type's links, down, or over its budget).
    pub fn allowed_from(
        &self,
        dccl_id: u32,
        link: LinkIndex,
        queued_at: Micros,
        len: usize,
    ) -> Option<Micros> {
        let rule = self.rule(dccl_id);
        let rank = rule.order.iter().position(|&l| l == link)?;
        if !self.available(link, len) {
            return None;
        }
        if rule.policy == LinkPolicy::FloodAll {
            return Some(queued_at);
        }
        // Each available link before this one has its turn of `timeout`.
        let turns = rule.order[..rank]
            .iter()
            .filter(|&&l| self.available(l, len))
            .count() as i64;
        Some(queued_at.saturating_add(rule.timeout.saturating_mul(turns)))
    }

    /// Whether `link` may carry a message of type `dccl_id` of `len` bytes
    /// queued at `queued_at`, at `now` ([`allowed_from`](Self::allowed_from)).
    pub fn may_carry(
        &self,
        dccl_id: u32,
        link: LinkIndex,
        queued_at: Micros,
        len: usize,
        now: Micros,
    ) -> bool {
        self.allowed_from(dccl_id, link, queued_at, len)
            .is_some_and(|t| t <= now)
    }

    /// For a message without ack given to `link`: whether it stays queued
    /// for another link of a flooding type that is available and has not
    /// carried it yet (`carried`: bit `i` set for each link `i` that has).
    pub fn others_to_carry(&self, dccl_id: u32, link: LinkIndex, carried: u8, len: usize) -> bool {
        let rule = self.rule(dccl_id);
        rule.policy == LinkPolicy::FloodAll
            && rule
                .order
                .iter()
                .any(|&l| l != link && carried & (1 << l) == 0 && self.available(l, len))
    }
}

/// The links a message was given to and not to be given to again: for
/// each, the frame that carried it (awaiting its ack there, or, without
/// ack, carried there by a flooding type).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct LinkMarks {
    mask: u8,
    frames: [u32; MAX_LINKS],
}

impl LinkMarks {
    /// The frame that carried it on `link`, if marked there.
    pub fn get(&self, link: LinkIndex) -> Option<u32> {
        (link < MAX_LINKS && self.mask & (1 << link) != 0).then(|| self.frames[link])
    }

    /// Marks it given to `link` in `frame`; returns whether it was not
    /// marked there before.
    pub fn set(&mut self, link: LinkIndex, frame: u32) -> bool {
        let new = self.get(link).is_none();
        self.mask |= 1 << link;
        self.frames[link] = frame;
        new
    }

    /// Unmarks `link`; returns whether it was marked.
    pub fn clear(&mut self, link: LinkIndex) -> bool {
        let was = self.get(link).is_some();
        self.mask &= !(1 << link);
        was
    }

    /// Bit `i` set for each link `i` marked.
    pub fn mask(&self) -> u8 {
        self.mask
    }

    /// The links marked.
    pub fn links(&self) -> impl Iterator<Item = LinkIndex> + '_ {
        (0..MAX_LINKS).filter(|&l| self.mask & (1 << l) != 0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: Micros = 1_000_000;

    fn links(costs: &[f64]) -> Links {
        Links::new(
            costs
                .iter()
                .enumerate()
                .map(|(i, &cost)| LinkSpec {
                    name: format!("l{i}"),
                    cost,
                    largest_frame: None,
                })
                .collect(),
        )
        .unwrap()
    }

    #[test]
    fn marks_keep_a_frame_per_link() {
        let mut m = LinkMarks::default();
        assert!(m.set(2, 7));
        assert!(!m.set(2, 8));
        assert_eq!(m.get(2), Some(8));
        assert_eq!(m.get(0), None);
        assert_eq!(m.mask(), 0b100);
        assert!(m.clear(2));
        assert!(!m.clear(2));
        assert_eq!(m.links().count(), 0);
    }

    #[test]
    fn rules_are_checked() {
        let mut l = links(&[1.0, 2.0]);
        assert!(l
            .set_rule(1, LinkRule::new(vec![], LinkPolicy::FloodAll, 1.0))
            .is_err());
        assert!(l
            .set_rule(1, LinkRule::new(vec![2], LinkPolicy::FloodAll, 1.0))
            .is_err());
        assert!(l
            .set_rule(1, LinkRule::new(vec![1, 1], LinkPolicy::FloodAll, 1.0))
            .is_err());
        assert!(Links::new(Vec::new()).is_err());
        assert_eq!(l.len(), 2);
        l.set_rule(1, LinkRule::new(vec![1], LinkPolicy::PriorityTimeout, 1.0))
            .unwrap();
        assert!(!l.several(1));
        assert!(l.several(9), "the default rule has every link");
    }

    #[test]
    fn the_default_rule_prefers_the_first_link() {
        let l = links(&[1.0, 1.0]);
        assert_eq!(l.allowed_from(9, 0, 10 * S, 5), Some(10 * S));
        assert_eq!(l.allowed_from(9, 1, 10 * S, 5), Some(130 * S));
    }

    #[test]
    fn a_link_whose_frames_are_too_small_is_skipped_at_once() {
        let mut l = links(&[1.0, 1.0]);
        l.specs[0].largest_frame = Some(10);
        assert_eq!(l.allowed_from(9, 0, 0, 20), None);
        assert_eq!(l.allowed_from(9, 1, 0, 20), Some(0));
        assert_eq!(l.allowed_from(9, 1, 0, 10), Some(120 * S));
    }

    #[test]
    fn cheapest_first_sorts_by_cost_keeping_ties_in_order() {
        let mut l = links(&[5.0, 1.0, 1.0]);
        l.set_rule(
            1,
            LinkRule::new(vec![0, 2, 1], LinkPolicy::CheapestFirst, 10.0),
        )
        .unwrap();
        assert_eq!(l.order(1), &[2, 1, 0]);
        assert_eq!(l.allowed_from(1, 0, 0, 1), Some(20 * S));
    }
}
