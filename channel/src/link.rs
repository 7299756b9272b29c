//! The link budget of an acoustic modem, SNR = SL − TL − NL + DI over its
//! band, and the frame-error rate each of its rates reaches at that SNR.
//!
//! The WHOI Micro-Modem's rates come with curves of frame-error rate
//! against in-band SNR:
//!
//! - PSK rates 1, 3 and 5: the measured points WHOI publishes with
//!   `ros_acomms` for its simulator (E. Gallimore et al., "ROS message
//!   transport over underwater acoustic links with ros_acomms", IEEE/OES
//!   AUV Symposium 2022), from Micro-Modem 2 measurements: rate 1 goes from
//!   every frame lost at −8.0 dB to none at −6.0 dB, rate 3 from −2.9 dB to
//!   2.5 % at 0.0 dB, rate 5 from 3.1 dB to none at 6.0 dB. Rate 3's
//!   measurements stop at 2.5 %: held beyond its last point, that would be
//!   a floor of 2.5 % lost frames at any SNR, which no modem has (rates 1
//!   and 5 reach none within a dB of their last percent). The curve goes on
//!   at its last segment's slope (−0.108 per dB) to none at +0.24 dB: one
//!   point of ours, beyond the measurements;
//! - FH-FSK rate 0: a logistic through the thesis' GLINT10 statistics
//!   (§4.3.3, N = 3350 transmissions, SL 190 dB, 25 kHz band C): fewer than
//!   1 % of frames got through above H = 108 dB, and H = 94 dB is the
//!   minimum-error threshold (half the frames); with this crate's Wenz noise
//!   at Beaufort 2 in the 4160 Hz band (69.7 dB, the sea of Fig. 4.8) these
//!   are SNR 12.3 dB (FER 0.99) and 26.3 dB (FER 0.5). It includes what the
//!   field added to ambient noise (the vehicle's own noise, multipath), so
//!   it is conservative; configure your own curve for other modems.
//!
//! Frame counts and sizes per rate are the Micro-Modem's (rate 0: one
//! 32-byte frame; FDP rates 1, 3, 5: 3 × 64, 2 × 256, 8 × 256 bytes). A
//! packet is lost when any of its frames is.

use serde::{Deserialize, Serialize};

use crate::error::{finite, positive, ChannelError};
use crate::noise::NoiseModel;

/// Frame-error rate against SNR (dB in the modem's band).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum FerCurve {
    /// Measured points `(snr dB, fer)`, SNR increasing; interpolated
    /// linearly, the end values held beyond them.
    Table(Vec<(f64, f64)>),
    /// `1 / (1 + exp((snr − snr50) / width))`.
    Logistic {
        /// SNR of FER 0.5 (dB).
        snr50: f64,
        /// Width (dB).
        width: f64,
    },
}

impl FerCurve {
    /// The frame-error rate at `snr` (dB), 0 to 1.
    pub fn fer(&self, snr: f64) -> f64 {
        if snr.is_nan() {
            return 1.0;
        }
        match self {
            FerCurve::Logistic { snr50, width } => 1.0 / (1.0 + ((snr - snr50) / width).exp()),
            FerCurve::Table(points) => {
                let Some(first) = points.first() else {
                    return 1.0;
                };
                if snr <= first.0 {
                    return first.1;
                }
                for w in points.windows(2) {
                    if snr <= w[1].0 {
                        let s = (snr - w[0].0) / (w[1].0 - w[0].0);
                        return w[0].1 + s * (w[1].1 - w[0].1);
                    }
                }
                points[points.len() - 1].1
            }
        }
    }

    fn validate(&self, field: &str) -> Result<(), ChannelError> {
        match self {
            FerCurve::Logistic { snr50, width } => {
                finite(&format!("{field}.snr50"), *snr50)?;
                positive(&format!("{field}.width"), *width)?;
            }
            FerCurve::Table(points) => {
                if points.is_empty() {
                    return Err(ChannelError::invalid(field, "an empty table"));
                }
                for (i, (s, f)) in points.iter().enumerate() {
                    finite(&format!("{field}[{i}].snr"), *s)?;
                    if !(0.0..=1.0).contains(f) {
                        return Err(ChannelError::invalid(
                            format!("{field}[{i}].fer"),
                            format!("{f} is not within 0 to 1"),
                        ));
                    }
                    if i > 0 && *s <= points[i - 1].0 {
                        return Err(ChannelError::invalid(
                            format!("{field}[{i}].snr"),
                            "SNRs must increase",
                        ));
                    }
                }
            }
        }
        Ok(())
    }
}

/// One rate of a modem.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RateModel {
    /// The modem's rate number.
    pub rate: u32,
    /// What it is (e.g. `FH-FSK`, `PSK FDP rate 5`).
    pub name: String,
    /// Frames per packet.
    pub frames: u32,
    /// Bytes per frame.
    pub frame_bytes: u32,
    /// Frame-error rate against SNR.
    pub fer: FerCurve,
}

impl RateModel {
    /// Probability that a packet (all its frames) is lost at `snr` (dB).
    pub fn packet_error(&self, snr: f64) -> f64 {
        1.0 - (1.0 - self.fer.fer(snr)).powi(self.frames as i32)
    }
}

/// An acoustic modem: its band, source level, directivity and rates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Modem {
    /// Its name.
    pub name: String,
    /// Carrier (centre) frequency (Hz).
    pub frequency: f64,
    /// Bandwidth (Hz).
    pub bandwidth: f64,
    /// Source level (dB re 1 µPa at 1 m).
    pub source_level: f64,
    /// Directivity index of the receiver (dB).
    #[serde(default)]
    pub directivity_index: f64,
    /// Its rates.
    pub rates: Vec<RateModel>,
}

/// The WHOI Micro-Modem's frequency bands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MicroModemBand {
    /// Band A: 10 kHz carrier, 5 kHz band.
    A,
    /// Band C: 25.12 kHz carrier, 4160 Hz band (the thesis' GLINT10,
    /// Table 4.1).
    C,
}

/// FER points of the PSK rates (SNR dB, FER), from WHOI's measurements
/// (see the module documentation).
const RATE1: [(f64, f64); 6] = [
    (-7.957, 1.0),
    (-7.604, 0.9367),
    (-7.234, 0.7267),
    (-6.845, 0.17),
    (-6.444, 0.02),
    (-6.012, 0.0),
];
const RATE3: [(f64, f64); 6] = [
    (-2.9215, 1.0),
    (-2.2806, 0.91),
    (-1.5853, 0.57),
    (-0.8275, 0.115),
    (0.0044, 0.025),
    // Not measured: the last segment's slope continued to zero.
    (0.2355, 0.0),
];
const RATE5: [(f64, f64); 3] = [(3.097, 1.0), (4.443, 0.135), (6.015, 0.0)];

impl Modem {
    /// The WHOI Micro-Modem in `band` with a 190 dB source level (the
    /// thesis' Table 4.1) and its rates 0, 1, 3 and 5.
    pub fn micromodem(band: MicroModemBand) -> Self {
        let (frequency, bandwidth) = match band {
            MicroModemBand::A => (10_000.0, 5_000.0),
            MicroModemBand::C => (25_120.0, 4_160.0),
        };
        let rate = |rate, name: &str, frames, frame_bytes, fer| RateModel {
            rate,
            name: name.into(),
            frames,
            frame_bytes,
            fer,
        };
        Modem {
            name: format!("WHOI Micro-Modem band {band:?}"),
            frequency,
            bandwidth,
            source_level: 190.0,
            directivity_index: 0.0,
            rates: vec![
                rate(
                    0,
                    "FH-FSK",
                    1,
                    32,
                    FerCurve::Logistic {
                        snr50: 26.3,
                        width: 3.05,
                    },
                ),
                rate(1, "PSK FDP rate 1", 3, 64, FerCurve::Table(RATE1.to_vec())),
                rate(3, "PSK FDP rate 3", 2, 256, FerCurve::Table(RATE3.to_vec())),
                rate(5, "PSK FDP rate 5", 8, 256, FerCurve::Table(RATE5.to_vec())),
            ],
        }
    }

    /// Checks the modem; the error names the bad field.
    pub fn validate(&self) -> Result<(), ChannelError> {
        positive("modem.frequency", self.frequency)?;
        positive("modem.bandwidth", self.bandwidth)?;
        if self.bandwidth >= 2.0 * self.frequency {
            return Err(ChannelError::invalid(
                "modem.bandwidth",
                "wider than twice the carrier",
            ));
        }
        finite("modem.source_level", self.source_level)?;
        finite("modem.directivity_index", self.directivity_index)?;
        if self.rates.is_empty() {
            return Err(ChannelError::invalid("modem.rates", "no rate"));
        }
        for (i, r) in self.rates.iter().enumerate() {
            if r.frames == 0 {
                return Err(ChannelError::invalid(
                    format!("modem.rates[{i}].frames"),
                    "no frame",
                ));
            }
            r.fer.validate(&format!("modem.rates[{i}].fer"))?;
        }
        Ok(())
    }

    /// The band (Hz) the modem's signal occupies.
    pub fn band(&self) -> (f64, f64) {
        (
            self.frequency - 0.5 * self.bandwidth,
            self.frequency + 0.5 * self.bandwidth,
        )
    }

    /// The noise level (dB re 1 µPa) of `noise` in the modem's band.
    pub fn noise_level(&self, noise: &NoiseModel) -> Result<f64, ChannelError> {
        let (lo, hi) = self.band();
        noise.band_level(lo, hi)
    }

    /// SNR (dB) at a transmission loss `tl` (dB) with noise level `nl`
    /// (dB): SL − TL − NL + DI.
    pub fn snr(&self, tl: f64, nl: f64) -> f64 {
        self.source_level - tl - nl + self.directivity_index
    }

    /// Frame- and packet-error rates of every rate at `snr` (dB).
    pub fn rates_at(&self, snr: f64) -> Vec<RateForecast> {
        self.rates
            .iter()
            .map(|r| RateForecast {
                rate: r.rate,
                fer: r.fer.fer(snr),
                packet_error: r.packet_error(snr),
            })
            .collect()
    }
}

/// How one rate fares on a link.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RateForecast {
    /// The rate.
    pub rate: u32,
    /// Frame-error rate (0 to 1).
    pub fer: f64,
    /// Probability that a packet of all the rate's frames is lost.
    pub packet_error: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_interpolate_and_hold_their_ends() {
        let m = Modem::micromodem(MicroModemBand::A);
        let r1 = &m.rates[1];
        assert_eq!(r1.fer.fer(-20.0), 1.0);
        assert_eq!(r1.fer.fer(20.0), 0.0);
        let mid = r1.fer.fer(-7.0);
        assert!(mid > 0.17 && mid < 0.7267, "{mid}");
        // Eight frames of rate 5 fail together more often than one.
        let r5 = &m.rates[3];
        assert!(r5.packet_error(4.443) > r5.fer.fer(4.443));
        assert!(m.validate().is_ok());
    }

    #[test]
    fn every_psk_rate_loses_no_frame_at_a_high_snr() {
        let m = Modem::micromodem(MicroModemBand::C);
        for r in &m.rates[1..] {
            assert_eq!(r.fer.fer(10.0), 0.0, "rate {}", r.rate);
            assert_eq!(r.packet_error(10.0), 0.0, "rate {}", r.rate);
        }
        // Rate 3 at its last measured point, and half-way to zero past it.
        let r3 = &m.rates[2].fer;
        assert!((r3.fer(0.0044) - 0.025).abs() < 1e-12);
        assert!((r3.fer(0.12) - 0.0125).abs() < 0.001, "{}", r3.fer(0.12));
    }

    #[test]
    fn the_fh_fsk_curve_follows_its_glint10_anchors() {
        // Re-derive the anchors from the noise model: SL 190, H 94 and 108.
        let m = Modem::micromodem(MicroModemBand::C);
        let nl = m.noise_level(&NoiseModel::beaufort(2, 0.5)).unwrap();
        assert!((nl - 69.7).abs() < 0.5, "{nl}");
        let r0 = &m.rates[0];
        assert!((r0.fer.fer(m.snr(94.0, nl)) - 0.5).abs() < 0.05);
        assert!((r0.fer.fer(m.snr(108.0, nl)) - 0.99).abs() < 0.01);
    }

    #[test]
    fn bad_curves_name_their_field() {
        let mut m = Modem::micromodem(MicroModemBand::C);
        m.rates[2].fer = FerCurve::Table(vec![(0.0, 0.5), (-1.0, 0.2)]);
        let e = m.validate().unwrap_err().to_string();
        assert!(e.starts_with("modem.rates[2].fer[1].snr"), "{e}");
    }
}
