//! A MAC switcher (as WHOI's ros_acomms has one): several named medium
//! access configurations, one of them the default, one active at a time.
//! A request switches to a named one, optionally with a keep-alive: unless
//! the same MAC is asked for again before the keep-alive runs out, the
//! node goes back to the default, so that a vehicle whose commanding
//! process died does not stay on a MAC nobody keeps an eye on.
//!
//! The switcher only decides which name runs and why; building the MAC
//! of that name, keeping the state on disk and telling it are its
//! caller's. It is a plain state machine driven by the time given to it
//! (microseconds since the UNIX epoch), with no clock of its own.

use crate::clock::Micros;

/// Why the active MAC is what it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SwitchReason {
    /// A request asked for it.
    Requested,
    /// A request asked again for the MAC already running: its keep-alive
    /// starts over.
    Renewed,
    /// The keep-alive ran out: the default runs again.
    KeepAliveLapsed,
    /// At start, the MAC kept from before the restart runs again, until
    /// the same deadline.
    Restored,
    /// At start, the keep-alive kept from before the restart had run out
    /// while the node was down: the default runs.
    KeepAliveLapsedWhileDown,
}

impl SwitchReason {
    /// Its name on the events: `requested`, `renewed`,
    /// `keep_alive_lapsed`, `restored`, `keep_alive_lapsed_while_down`.
    pub fn name(self) -> &'static str {
        match self {
            SwitchReason::Requested => "requested",
            SwitchReason::Renewed => "renewed",
            SwitchReason::KeepAliveLapsed => "keep_alive_lapsed",
            SwitchReason::Restored => "restored",
            SwitchReason::KeepAliveLapsedWhileDown => "keep_alive_lapsed_while_down",
        }
    }
}

/// A change of the active MAC (or a renewal of the one running).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Switch {
    /// The MAC that ran before.
    pub from: String,
    /// The MAC that runs now.
    pub to: String,
    /// Why.
    pub reason: SwitchReason,
    /// When `to` lapses (microseconds since the epoch); `None`: it runs
    /// until switched again.
    pub until: Option<Micros>,
}

impl Switch {
    /// Whether another MAC runs now (not a renewal of the same one).
    pub fn changed(&self) -> bool {
        self.from != self.to
    }
}

/// Which of the named MACs runs, and until when.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Switcher {
    names: Vec<String>,
    default: usize,
    active: usize,
    until: Option<Micros>,
}

impl Switcher {
    /// A switcher over `names` running `default`. `None` when `default`
    /// is not among `names`.
    pub fn new(names: Vec<String>, default: &str) -> Option<Self> {
        let default = names.iter().position(|n| n == default)?;
        Some(Switcher {
            names,
            default,
            active: default,
            until: None,
        })
    }

    /// The names, in the order given.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The name of the MAC running.
    pub fn active(&self) -> &str {
        &self.names[self.active]
    }

    /// The name of the default MAC.
    pub fn default_name(&self) -> &str {
        &self.names[self.default]
    }

    /// When the running MAC lapses (`None`: it does not).
    pub fn until(&self) -> Option<Micros> {
        self.until
    }

    /// Switches to `name` at `now`, to run for `keep_alive` microseconds
    /// unless asked for again (`None`: until switched again; the default
    /// never lapses, a keep-alive given with it is ignored). Errors: no
    /// MAC has that name, or the keep-alive is not positive (the error
    /// says which).
    pub fn request(
        &mut self,
        name: &str,
        keep_alive: Option<Micros>,
        now: Micros,
    ) -> Result<Switch, String> {
        let to = self.index_of(name)?;
        if let Some(k) = keep_alive.filter(|&k| k <= 0) {
            return Err(format!(
                "keep_alive {} s is not positive (leave it out for no keep-alive)",
                k as f64 / 1e6
            ));
        }
        let reason = if to == self.active && to != self.default {
            SwitchReason::Renewed
        } else {
            SwitchReason::Requested
        };
        let until = keep_alive
            .filter(|_| to != self.default)
            .map(|k| now.saturating_add(k));
        Ok(self.go(to, until, reason))
    }

    /// Goes back to the default when the keep-alive has run out at `now`.
    pub fn lapse(&mut self, now: Micros) -> Option<Switch> {
        let until = self.until?;
        (now >= until).then(|| self.go(self.default, None, SwitchReason::KeepAliveLapsed))
    }

    /// At start (`now`), runs the state kept before a restart: `active`
    /// until `until`, or the default when that has passed. Errors: no MAC
    /// has that name.
    pub fn restore(
        &mut self,
        active: &str,
        until: Option<Micros>,
        now: Micros,
    ) -> Result<Switch, String> {
        let to = self.index_of(active)?;
        if until.is_some_and(|u| now >= u) {
            // From the MAC that ran before the restart, which lapsed.
            let mut lapsed = self.go(self.default, None, SwitchReason::KeepAliveLapsedWhileDown);
            lapsed.from = active.to_string();
            return Ok(lapsed);
        }
        Ok(self.go(to, until, SwitchReason::Restored))
    }

    fn index_of(&self, name: &str) -> Result<usize, String> {
        self.names.iter().position(|n| n == name).ok_or_else(|| {
            format!(
                "no MAC named \"{name}\" (the switcher's MACs: {})",
                self.names.join(", ")
            )
        })
    }

    fn go(&mut self, to: usize, until: Option<Micros>, reason: SwitchReason) -> Switch {
        let from = self.active().to_string();
        self.active = to;
        self.until = until;
        Switch {
            from,
            to: self.active().to_string(),
            reason,
            until,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const S: Micros = 1_000_000;

    fn switcher() -> Switcher {
        Switcher::new(vec!["survey".into(), "quiet".into()], "survey").unwrap()
    }

    #[test]
    fn a_default_not_among_the_names_is_refused() {
        assert!(Switcher::new(vec!["a".into()], "b").is_none());
    }

    #[test]
    fn a_switch_with_a_keep_alive_lapses_to_the_default_unless_renewed() {
        let mut s = switcher();
        let sw = s.request("quiet", Some(60 * S), 0).unwrap();
        assert_eq!(
            (sw.from.as_str(), sw.to.as_str(), sw.reason, sw.until),
            ("survey", "quiet", SwitchReason::Requested, Some(60 * S))
        );
        assert!(sw.changed());
        assert_eq!(s.lapse(59 * S), None);
        let renewed = s.request("quiet", Some(60 * S), 50 * S).unwrap();
        assert_eq!(renewed.reason, SwitchReason::Renewed);
        assert!(!renewed.changed());
        assert_eq!(s.lapse(100 * S), None);
        let back = s.lapse(110 * S).unwrap();
        assert_eq!(
            (back.from.as_str(), back.to.as_str(), back.reason),
            ("quiet", "survey", SwitchReason::KeepAliveLapsed)
        );
        assert_eq!((s.active(), s.until()), ("survey", None));
        assert_eq!(s.lapse(1000 * S), None);
    }

    #[test]
    fn without_a_keep_alive_a_switch_holds_and_the_default_never_lapses() {
        let mut s = switcher();
        s.request("quiet", None, 0).unwrap();
        assert_eq!(s.lapse(i64::MAX), None);
        let sw = s.request("survey", Some(5 * S), 0).unwrap();
        assert_eq!((sw.to.as_str(), sw.until), ("survey", None));
    }

    #[test]
    fn unknown_names_and_keep_alives_that_are_not_positive_are_refused() {
        let mut s = switcher();
        let err = s.request("loud", None, 0).unwrap_err();
        assert!(
            err.contains("\"loud\"") && err.contains("survey, quiet"),
            "{err}"
        );
        let err = s.request("quiet", Some(0), 0).unwrap_err();
        assert!(err.contains("keep_alive"), "{err}");
        assert_eq!(s.active(), "survey");
    }

    #[test]
    fn a_restart_keeps_the_deadline_or_reverts_when_it_passed_while_down() {
        let mut s = switcher();
        let sw = s.restore("quiet", Some(100 * S), 40 * S).unwrap();
        assert_eq!(
            (sw.reason, sw.until),
            (SwitchReason::Restored, Some(100 * S))
        );
        assert_eq!(s.active(), "quiet");
        let mut s = switcher();
        let sw = s.restore("quiet", Some(100 * S), 100 * S).unwrap();
        assert_eq!(
            (sw.reason, sw.from.as_str(), sw.to.as_str()),
            (SwitchReason::KeepAliveLapsedWhileDown, "quiet", "survey")
        );
    }
}
