//! The modem rate chosen from the link: for a slot with `adaptive_rate`,
//! the WHOI Micro-Modem rate to a destination is picked from the SNR of
//! the recent receptions from it (`snr_in` of the modem's `$CACST`
//! receive statistics) and, where the link forecast runs, from its
//! per-rate frame-error rate to that peer.
//!
//! Each rate's chance of losing a packet is estimated from the median of
//! the last [`Settings::window`] SNRs heard from the peer, through the
//! rate's curve of frame-error rate against in-band SNR
//! ([`channel::Modem::micromodem`]: WHOI's measured PSK curves, the
//! thesis' FH-FSK statistics), and from the forecast's frame-error rate;
//! with both, the worse counts. The fastest rate (most bytes a packet)
//! whose packet-error estimate is at most [`Settings::target_packet_error`]
//! is chosen among the rates whose packet fits the slot; when none meets
//! it, the fitting rate least likely to lose its packet. Hysteresis keeps
//! it from flapping: a faster rate than the current one is taken only
//! when it meets the target [`Settings::hysteresis_db`] below the
//! measured SNR; the current rate is kept while it meets the target at
//! the SNR itself. With no reception and no forecast, the slot's own rate
//! is used.
//!
//! [`choose`] is a pure function of its inputs; [`SnrHistory`] keeps the
//! SNRs heard.

use std::collections::{HashMap, VecDeque};

use channel::RateModel;

/// How rates are chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Highest acceptable chance of losing a packet (0 to 1).
    pub target_packet_error: f64,
    /// SNR margin (dB) a faster rate must meet the target with before it
    /// is taken.
    pub hysteresis_db: f64,
    /// Receptions per peer whose SNR counts (their median).
    pub window: usize,
}

impl Default for Settings {
    /// A packet in ten lost at most, 2 dB of hysteresis, the last five
    /// receptions.
    fn default() -> Self {
        Settings {
            target_packet_error: 0.1,
            hysteresis_db: 2.0,
            window: 5,
        }
    }
}

pub use crate::event::modem::{Choice, Reason};

/// A rate the slot may use: its model and whether its packet fits.
#[derive(Debug, Clone, Copy)]
pub struct Candidate<'a> {
    /// The rate's frames and frame-error curve.
    pub model: &'a RateModel,
    /// Its packet fits the slot's length.
    pub fits: bool,
}

/// What is known of the link to the destination.
#[derive(Debug, Clone, Copy, Default)]
pub struct LinkData<'a> {
    /// The SNR estimate from recent receptions (dB).
    pub snr: Option<f64>,
    /// The forecast's frame-error rate by rate (`(rate, fer)`).
    pub forecast: &'a [(u32, f64)],
}

/// The rate for the next transmission (see the module's documentation):
/// `current` the rate chosen last for this destination, `configured`
/// the slot's own rate, `candidates` the modem's rates.
pub fn choose(
    current: Option<i32>,
    configured: i32,
    link: LinkData<'_>,
    candidates: &[Candidate<'_>],
    settings: &Settings,
) -> Choice {
    let none = Choice {
        rate: configured,
        reason: Reason::NoLinkData,
        snr: link.snr,
        packet_error: None,
        slot_limited: false,
    };
    if link.snr.is_none() && link.forecast.is_empty() {
        return none;
    }
    let mut ordered: Vec<&Candidate<'_>> = candidates.iter().collect();
    ordered.sort_by_key(|c| c.model.frames * c.model.frame_bytes);
    let packet_error = |c: &Candidate<'_>, margin: f64| -> f64 {
        let measured = link.snr.map(|s| c.model.packet_error(s - margin));
        let forecast = link
            .forecast
            .iter()
            .find(|(r, _)| *r == c.model.rate)
            .map(|(_, fer)| 1.0 - (1.0 - fer.clamp(0.0, 1.0)).powi(c.model.frames as i32));
        measured.into_iter().chain(forecast).fold(0.0, f64::max)
    };
    let target = settings.target_packet_error;
    let best = |margin: f64, fitting: bool| {
        ordered
            .iter()
            .rev()
            .find(|c| (c.fits || !fitting) && packet_error(c, margin) <= target)
            .copied()
    };
    // When none meets the target: the fitting rate least likely to lose
    // its packet (the smallest of those equally likely). The smallest
    // packet is not always the most robust: rate 0's FH-FSK loses more
    // than rate 1's PSK at every SNR of the curves.
    let most_robust = ordered
        .iter()
        .filter(|c| c.fits)
        .min_by(|a, b| packet_error(a, 0.0).total_cmp(&packet_error(b, 0.0)))
        .copied();
    let current = current.and_then(|r| ordered.iter().find(|c| c.fits && c.model.rate as i32 == r));
    let size = |c: &Candidate<'_>| c.model.frames * c.model.frame_bytes;
    let (chosen, reason) = match current {
        Some(cur) => match best(settings.hysteresis_db, true) {
            Some(up) if size(up) > size(cur) => (Some(up), Reason::Up),
            _ if packet_error(cur, 0.0) <= target => (Some(*cur), Reason::Kept),
            _ => (best(0.0, true).or(most_robust), Reason::Down),
        },
        None => (best(0.0, true).or(most_robust), Reason::First),
    };
    let Some(chosen) = chosen else {
        return none;
    };
    let slot_limited = best(0.0, false).is_some_and(|b| size(b) > size(chosen));
    Choice {
        rate: chosen.model.rate as i32,
        reason,
        snr: link.snr,
        packet_error: Some(packet_error(chosen, 0.0)),
        slot_limited,
    }
}

/// The SNRs of the recent receptions, by the peer heard.
#[derive(Debug, Clone, Default)]
pub struct SnrHistory {
    by_peer: HashMap<i32, VecDeque<f64>>,
}

impl SnrHistory {
    /// Keeps `snr` (dB) heard from `peer`, the last `window` of each.
    pub fn heard(&mut self, peer: i32, snr: f64, window: usize) {
        if !snr.is_finite() {
            return;
        }
        let heard = self.by_peer.entry(peer).or_default();
        heard.push_back(snr);
        while heard.len() > window.max(1) {
            heard.pop_front();
        }
    }

    /// The median SNR heard from `peer`; for a broadcast (0) or a
    /// destination left to the queue (-1), the lowest of every peer's.
    pub fn estimate(&self, peer: i32) -> Option<f64> {
        if peer > 0 {
            return self.by_peer.get(&peer).and_then(median);
        }
        self.by_peer.values().filter_map(median).reduce(f64::min)
    }
}

fn median(values: &VecDeque<f64>) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use channel::{MicroModemBand, Modem};

    fn rates() -> Vec<RateModel> {
        Modem::micromodem(MicroModemBand::C).rates
    }

    fn all_fit(models: &[RateModel]) -> Vec<Candidate<'_>> {
        models
            .iter()
            .map(|model| Candidate { model, fits: true })
            .collect()
    }

    fn at(snr: f64) -> LinkData<'static> {
        LinkData {
            snr: Some(snr),
            forecast: &[],
        }
    }

    #[test]
    fn the_fastest_rate_meeting_the_target_is_chosen_and_nothing_known_keeps_the_slots() {
        let models = rates();
        let c = all_fit(&models);
        let s = Settings::default();
        let pick = |snr| choose(None, 1, at(snr), &c, &s);
        assert_eq!(pick(10.0).rate, 5);
        assert_eq!(pick(3.0).rate, 3);
        assert_eq!(pick(-5.0).rate, 1);
        assert_eq!(pick(-20.0).rate, 0, "every rate loses all: the slowest");
        // At -7 dB none meets the target; rate 1 loses the least (rate
        // 0's FSK loses more than rate 1's PSK).
        let weak = pick(-7.0);
        assert!(weak.packet_error.unwrap() > 0.1, "{weak:?}");
        assert_eq!(weak.rate, 1, "nothing meets it: the most robust");
        let models = rates();
        let error = |rate: u32| {
            models
                .iter()
                .find(|m| m.rate == rate)
                .unwrap()
                .packet_error(-7.0)
        };
        assert!(error(1) < error(0), "{} {}", error(1), error(0));
        assert_eq!(pick(10.0).reason, Reason::First);
        let none = choose(Some(5), 1, LinkData::default(), &c, &s);
        assert_eq!((none.rate, none.reason), (1, Reason::NoLinkData));
    }

    #[test]
    fn hysteresis_keeps_a_rate_near_its_threshold_from_flapping() {
        let models = rates();
        let c = all_fit(&models);
        let s = Settings::default();
        // Rate 5 meets 10 % a packet near 6 dB: without the 2 dB margin
        // these SNRs around it would switch it on and off.
        let mut rate = 3;
        let mut changes = 0;
        for snr in [4.0, 6.0, 5.0, 6.5, 5.5, 6.0, 4.9, 6.4] {
            let choice = choose(Some(rate), 1, at(snr), &c, &s);
            if choice.rate != rate {
                changes += 1;
            }
            rate = choice.rate;
        }
        assert_eq!((rate, changes), (3, 0), "no margin met: stays at 3");
        let up = choose(Some(3), 1, at(8.0), &c, &s);
        assert_eq!((up.rate, up.reason), (5, Reason::Up));
        let kept = choose(Some(5), 1, at(6.0), &c, &s);
        assert_eq!((kept.rate, kept.reason), (5, Reason::Kept));
        let down = choose(Some(5), 1, at(3.0), &c, &s);
        assert_eq!((down.rate, down.reason), (3, Reason::Down));
    }

    #[test]
    fn the_slot_bounds_the_rate_and_the_forecast_counts_when_worse() {
        let models = rates();
        let mut c = all_fit(&models);
        c.iter_mut()
            .filter(|c| c.model.rate == 5)
            .for_each(|c| c.fits = false);
        let s = Settings::default();
        let bounded = choose(None, 1, at(20.0), &c, &s);
        assert_eq!((bounded.rate, bounded.slot_limited), (3, true));
        // The forecast says rate 3 loses half its frames: rate 1.
        let forecast = [(3, 0.5), (1, 0.0)];
        let link = LinkData {
            snr: Some(20.0),
            forecast: &forecast,
        };
        assert_eq!(choose(None, 1, link, &c, &s).rate, 1);
        // The forecast alone.
        let link = LinkData {
            snr: None,
            forecast: &[(0, 0.0), (1, 0.0), (3, 0.01), (5, 0.9)],
        };
        assert_eq!(choose(None, 0, link, &all_fit(&models), &s).rate, 3);
    }

    #[test]
    fn the_snr_is_the_median_of_the_last_receptions_and_the_worst_peer_for_all() {
        let mut h = SnrHistory::default();
        for snr in [1.0, 30.0, 2.0, 3.0, 4.0, 5.0] {
            h.heard(2, snr, 5);
        }
        assert_eq!(h.estimate(2), Some(4.0));
        h.heard(3, -4.0, 5);
        assert_eq!(h.estimate(0), Some(-4.0));
        assert_eq!(h.estimate(-1), Some(-4.0));
        assert_eq!(h.estimate(7), None);
        h.heard(7, f64::NAN, 5);
        assert_eq!(h.estimate(7), None);
    }
}
