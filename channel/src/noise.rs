//! Ambient noise of the sea: the Wenz curves in the empirical form of
//! Coates (turbulence, distant shipping, wind-driven surface noise,
//! thermal noise), summed in power, and the level over a modem's band.
//!
//! Sources: G. M. Wenz, "Acoustic ambient noise in the ocean: spectra and
//! sources", JASA 34 (1962) 1936; R. Coates, *Underwater Acoustic Systems*
//! (Macmillan, 1990), the formulas as M. Stojanovic uses them in "On the
//! relationship between capacity and distance in an underwater acoustic
//! communication channel", ACM SIGMOBILE MC2R 11 (2007) 34. The Beaufort
//! scale's wind speeds are the WMO's (mid-range of each force).

use serde::{Deserialize, Serialize};

use crate::error::{non_negative, positive, ChannelError};

/// The noise field at a place.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseModel {
    /// Wind speed at 10 m (m/s).
    pub wind_speed: f64,
    /// Shipping activity, 0 (none) to 1 (heavy).
    pub shipping: f64,
}

impl Default for NoiseModel {
    /// Beaufort 2 (the thesis' GLINT10 sea, Fig. 4.8), moderate shipping.
    fn default() -> Self {
        NoiseModel::beaufort(2, 0.5)
    }
}

/// Mid-range wind speed (m/s) of each Beaufort force 0–12 (WMO).
const BEAUFORT: [f64; 13] = [
    0.1, 0.9, 2.45, 4.4, 6.7, 9.35, 12.3, 15.5, 18.95, 22.6, 26.45, 30.55, 34.0,
];

impl NoiseModel {
    /// The noise of Beaufort force `force` (0–12, larger is taken as 12)
    /// with `shipping` activity (0–1).
    pub fn beaufort(force: u32, shipping: f64) -> Self {
        NoiseModel {
            wind_speed: BEAUFORT[(force as usize).min(12)],
            shipping,
        }
    }

    /// Checks the model; the error names the bad field.
    pub fn validate(&self) -> Result<(), ChannelError> {
        non_negative("noise.wind_speed", self.wind_speed)?;
        non_negative("noise.shipping", self.shipping)?;
        if self.shipping > 1.0 {
            return Err(ChannelError::invalid(
                "noise.shipping",
                format!("{} is not within 0 to 1", self.shipping),
            ));
        }
        Ok(())
    }

    /// Power spectral density (dB re 1 µPa²/Hz) at `frequency` (Hz).
    pub fn spectrum_level(&self, frequency: f64) -> f64 {
        let f = (frequency / 1000.0).max(1e-6);
        let lf = f.log10();
        let turbulence = 17.0 - 30.0 * lf;
        let shipping = 40.0 + 20.0 * (self.shipping - 0.5) + 26.0 * lf - 60.0 * (f + 0.03).log10();
        let wind = 50.0 + 7.5 * self.wind_speed.sqrt() + 20.0 * lf - 40.0 * (f + 0.4).log10();
        let thermal = -15.0 + 20.0 * lf;
        let power: f64 = [turbulence, shipping, wind, thermal]
            .iter()
            .map(|db| 10f64.powf(db / 10.0))
            .sum();
        10.0 * power.log10()
    }

    /// Noise level (dB re 1 µPa) over `low..high` Hz: the spectrum
    /// integrated over the band.
    pub fn band_level(&self, low: f64, high: f64) -> Result<f64, ChannelError> {
        positive("band.low", low)?;
        positive("band.high", high)?;
        if high <= low {
            return Err(ChannelError::invalid(
                "band.high",
                format!("{high} Hz is not above {low} Hz"),
            ));
        }
        const STEPS: usize = 256;
        let df = (high - low) / STEPS as f64;
        let p = |f: f64| 10f64.powf(self.spectrum_level(f) / 10.0);
        let inner: f64 = (1..STEPS).map(|i| p(low + i as f64 * df)).sum();
        let power = df * (0.5 * (p(low) + p(high)) + inner);
        Ok(10.0 * power.log10())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wind_dominates_at_modem_frequencies_and_grows_with_wind() {
        let calm = NoiseModel::beaufort(1, 0.5);
        let rough = NoiseModel::beaufort(6, 0.5);
        let (a, b) = (
            calm.spectrum_level(25_000.0),
            rough.spectrum_level(25_000.0),
        );
        assert!(b > a + 10.0, "{a} {b}");
        // Wenz: about 30–45 dB re µPa²/Hz at 25 kHz in light winds.
        assert!((25.0..50.0).contains(&a), "{a}");
        // Shipping matters at 100 Hz, not at 25 kHz.
        let busy = NoiseModel {
            shipping: 1.0,
            ..calm
        };
        assert!(busy.spectrum_level(100.0) > calm.spectrum_level(100.0) + 5.0);
        assert!((busy.spectrum_level(25_000.0) - a).abs() < 0.5);
    }

    #[test]
    fn band_level_adds_ten_log_bandwidth() {
        let n = NoiseModel::default();
        let band = n.band_level(24_000.0, 26_000.0).unwrap();
        let spot = n.spectrum_level(25_000.0) + 10.0 * 2000f64.log10();
        assert!((band - spot).abs() < 0.3, "{band} {spot}");
        assert!(n
            .band_level(26_000.0, 24_000.0)
            .unwrap_err()
            .to_string()
            .starts_with("band.high"));
    }
}
