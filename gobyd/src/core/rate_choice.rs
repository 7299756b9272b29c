//! The core's side of the rate chosen from the link
//! ([`adaptive_rate`](super::link::adaptive_rate)): the SNR of each
//! reception (a Micro-Modem's `$CACST` `snr_in`) is kept by the peer
//! heard, the link forecast's per-rate frame-error rates by peer as they
//! come; when this node initiates a slot with `adaptive_rate` (or a cycle
//! with it), its transmission's rate is chosen from them for the slot's
//! destination, bounded by what fits the time left in the slot, and the
//! choice told on the `mac` events (`mac_rate`).

use std::collections::HashMap;
use std::time::Duration;

use channel::{MicroModemBand, Modem, RateModel};
use modemdriver::ModemTransmission;
use protos::goby::acomms::protobuf::DriverConfig;

use super::link::adaptive_rate::{choose, Candidate, LinkData, Settings, SnrHistory};
use super::Core;
use crate::event::{DaemonEvent, ForecastEvent, ModemEvent};

/// What a link keeps to choose rates from.
#[derive(Debug, Default)]
pub struct RateChooser {
    /// SNRs heard, by peer.
    history: SnrHistory,
    /// The rate chosen last, by destination.
    current: HashMap<i32, i32>,
    /// The last forecast's frame-error rates, by peer (`(rate, fer)`).
    forecast: HashMap<i32, Vec<(u32, f64)>>,
}

/// The Micro-Modem's rates with their curves of frame-error rate.
fn models() -> Vec<RateModel> {
    Modem::micromodem(MicroModemBand::C).rates
}

/// Whether a packet of `rate` fits `seconds` on `driver` (its packet
/// time; without a driver's configuration, the rate's frames alone).
fn fits(driver: Option<&DriverConfig>, rate: i32, seconds: f64) -> bool {
    let packet = match driver {
        Some(d) => modemdriver::check::data_packet_time(d, rate).map(|p| p.shortest_slot()),
        None => modemdriver::rate::spec(rate).map(|s| s.packet_duration(Duration::ZERO)),
    };
    packet.is_some_and(|p| p.as_secs_f64() <= seconds)
}

impl Core {
    /// Keeps the SNR of a reception on link `i` (Micro-Modem receive
    /// statistics; other drivers report none).
    pub(super) fn heard_snr(&mut self, i: usize, transmission: &ModemTransmission) {
        let window = Settings::default().window;
        for stat in &transmission.receive_stat {
            if let Some(snr) = stat.snr_in {
                let peer = stat.source.unwrap_or(transmission.src());
                self.links[i]
                    .rates
                    .history
                    .heard(peer, f64::from(snr), window);
            }
        }
    }

    /// The forecasts that came since the last look, kept by peer.
    fn take_forecasts(&mut self, i: usize) {
        while let Ok(event) = self.own_events.0.try_recv().or_else(|e| match e {
            tokio::sync::broadcast::error::TryRecvError::Lagged(_) => self.own_events.0.try_recv(),
            other => Err(other),
        }) {
            if let DaemonEvent::Forecast(ForecastEvent::Forecast(f)) = &*event {
                self.links[i].rates.forecast = f
                    .peers
                    .iter()
                    .map(|p| (p.node, p.rates.iter().map(|r| (r.rate, r.fer)).collect()))
                    .collect();
            }
        }
    }

    /// Chooses the rate of `transmission` (initiated by this node on link
    /// `i` in a slot with `adaptive_rate`, or a cycle with it) and tells
    /// the choice; other slots are left alone.
    pub(super) fn adapt_rate(&mut self, i: usize, transmission: &mut ModemTransmission) {
        let cycle_wide = self.links[i].adaptive_rate;
        if !(cycle_wide || transmission.adaptive_rate()) {
            return;
        }
        self.take_forecasts(i);
        let dest = transmission.dest();
        let link = &self.links[i];
        let models = models();
        let candidates: Vec<Candidate<'_>> = models
            .iter()
            .map(|model| Candidate {
                model,
                fits: fits(
                    link.config.as_ref(),
                    model.rate as i32,
                    transmission.slot_seconds(),
                ),
            })
            .collect();
        let forecast: Vec<(u32, f64)> = if dest > 0 {
            link.rates.forecast.get(&dest).cloned().unwrap_or_default()
        } else {
            // For every peer: each rate at its worst peer's.
            let mut worst: HashMap<u32, f64> = HashMap::new();
            for (rate, fer) in link.rates.forecast.values().flatten() {
                let w = worst.entry(*rate).or_insert(0.0);
                *w = w.max(*fer);
            }
            worst.into_iter().collect()
        };
        let data = LinkData {
            snr: link.rates.history.estimate(dest),
            forecast: &forecast,
        };
        let current = link.rates.current.get(&dest).copied();
        let choice = choose(
            current,
            transmission.rate(),
            data,
            &candidates,
            &Settings::default(),
        );
        transmission.rate = Some(choice.rate);
        self.links[i].rates.current.insert(dest, choice.rate);
        tracing::debug!(
            dest,
            rate = choice.rate,
            reason = choice.reason.name(),
            snr = choice.snr,
            "rate chosen from the link"
        );
        self.report(
            i,
            ModemEvent::RateChoice {
                dest,
                slot_index: transmission.slot_index(),
                choice,
            },
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_a_drivers_settings_a_rate_fits_when_its_frames_do() {
        // Rate 5: 8 frames of 256 bytes at 5300 bit/s, about 3.1 s.
        assert!(fits(None, 5, 4.0));
        assert!(!fits(None, 5, 3.0));
        assert!(!fits(None, 9, 100.0));
    }
}
