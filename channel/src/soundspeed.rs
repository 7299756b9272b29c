//! Sound speed in sea water from temperature, salinity and depth (or
//! pressure), and the pressure at a depth.
//!
//! Sources: C.-T. Chen and F. J. Millero, "Speed of sound in seawater at
//! high pressures", JASA 62 (1977) 1129, the UNESCO algorithm of N. P.
//! Fofonoff and R. C. Millard, UNESCO Tech. Pap. Mar. Sci. 44 (1983), with
//! the coefficients G. S. K. Wong and S. Zhu recomputed for ITS-90 (JASA 97
//! (1995) 1732): what the thesis' GLINT10 profiles used (Fig. 4.4);
//! K. V. Mackenzie, "Nine-term equation for sound speed in the oceans",
//! JASA 70 (1981) 807; P. M. Saunders, "Practical conversion of pressure to
//! depth", J. Phys. Oceanogr. 11 (1981) 573.

use serde::{Deserialize, Serialize};

use crate::error::{finite, non_negative, ChannelError};

/// Which equation turns a CTD sample into a sound speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Formula {
    /// UNESCO (Chen–Millero 1977, Wong–Zhu 1995 coefficients): 0–40 °C,
    /// 0–40 psu, 0–1000 bar.
    #[default]
    ChenMillero,
    /// Mackenzie's nine-term equation: −2–30 °C, 25–40 psu, 0–8000 m.
    Mackenzie,
}

/// Sea pressure (dbar, 0 at the surface) at `depth` (m) and `latitude`
/// (degrees), after Saunders (1981).
pub fn pressure_dbar(depth: f64, latitude: f64) -> f64 {
    let s = latitude.to_radians().sin();
    let c1 = (5.92 + 5.25 * s * s) * 1e-3;
    ((1.0 - c1) - ((1.0 - c1).powi(2) - 8.84e-6 * depth).max(0.0).sqrt()) / 4.42e-6
}

/// Sound speed (m/s) by the UNESCO equation at `temperature` (°C, ITS-90),
/// `salinity` (psu) and sea pressure `pressure_bar` (bar).
pub fn chen_millero(temperature: f64, salinity: f64, pressure_bar: f64) -> f64 {
    let (t, s, p) = (temperature, salinity, pressure_bar);
    let poly = |c: &[f64]| c.iter().rev().fold(0.0, |acc, k| acc * t + k);
    let cw = poly(&[
        1402.388,
        5.03830,
        -5.81090e-2,
        3.3432e-4,
        -1.47797e-6,
        3.1419e-9,
    ]) + poly(&[0.153563, 6.8999e-4, -8.1829e-6, 1.3632e-7, -6.1260e-10]) * p
        + poly(&[3.1260e-5, -1.7111e-6, 2.5986e-8, -2.5353e-10, 1.0415e-12]) * p * p
        + poly(&[-9.7729e-9, 3.8513e-10, -2.3654e-12]) * p * p * p;
    let a = poly(&[1.389, -1.262e-2, 7.166e-5, 2.008e-6, -3.21e-8])
        + poly(&[9.4742e-5, -1.2583e-5, -6.4928e-8, 1.0515e-8, -2.0142e-10]) * p
        + poly(&[-3.9064e-7, 9.1061e-9, -1.6009e-10, 7.994e-12]) * p * p
        + poly(&[1.100e-10, 6.651e-12, -3.391e-13]) * p * p * p;
    let b = -1.922e-2 - 4.42e-5 * t + (7.3637e-5 + 1.7950e-7 * t) * p;
    let d = 1.727e-3 - 7.9836e-6 * p;
    cw + a * s + b * s.powf(1.5) + d * s * s
}

/// Sound speed (m/s) by Mackenzie's equation at `temperature` (°C),
/// `salinity` (psu) and `depth` (m).
pub fn mackenzie(temperature: f64, salinity: f64, depth: f64) -> f64 {
    let (t, s, d) = (temperature, salinity, depth);
    1448.96 + 4.591 * t - 5.304e-2 * t * t
        + 2.374e-4 * t * t * t
        + 1.340 * (s - 35.0)
        + 1.630e-2 * d
        + 1.675e-7 * d * d
        - 1.025e-2 * t * (s - 35.0)
        - 7.139e-13 * t * d * d * d
}

/// One CTD sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CtdSample {
    /// When it was taken (s, any epoch, the same for all samples).
    pub time: f64,
    /// Depth (m).
    pub depth: f64,
    /// Temperature (°C).
    pub temperature: f64,
    /// Salinity (psu).
    pub salinity: f64,
}

impl CtdSample {
    /// Checks the sample; the error names the bad field.
    pub fn validate(&self) -> Result<(), ChannelError> {
        finite("sample.time", self.time)?;
        non_negative("sample.depth", self.depth)?;
        finite("sample.temperature", self.temperature)?;
        non_negative("sample.salinity", self.salinity)?;
        if !(-3.0..=45.0).contains(&self.temperature) {
            return Err(ChannelError::invalid(
                "sample.temperature",
                format!("{} °C is not sea water", self.temperature),
            ));
        }
        if self.salinity > 45.0 {
            return Err(ChannelError::invalid(
                "sample.salinity",
                format!("{} psu is not sea water", self.salinity),
            ));
        }
        Ok(())
    }

    /// The sound speed (m/s) of this sample by `formula` at `latitude`
    /// (degrees, for the pressure).
    pub fn sound_speed(&self, formula: Formula, latitude: f64) -> f64 {
        match formula {
            Formula::ChenMillero => chen_millero(
                self.temperature,
                self.salinity,
                pressure_dbar(self.depth, latitude) / 10.0,
            ),
            Formula::Mackenzie => mackenzie(self.temperature, self.salinity, self.depth),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unesco_check_values() {
        // Fofonoff & Millard (1983) check value: 40 psu, 40 °C, 1000 bar:
        // 1731.995 m/s (IPTS-68; the ITS-90 coefficients differ by less
        // than 0.1 m/s there).
        assert!((chen_millero(40.0, 40.0, 1000.0) - 1731.995).abs() < 0.1);
        // Surface water, 35 psu, 10 °C: 1489.8 m/s.
        assert!((chen_millero(10.0, 35.0, 0.0) - 1489.8).abs() < 0.1);
    }

    #[test]
    fn mackenzie_check_value() {
        // Mackenzie (1981): 25 °C, 35 psu, 1000 m: 1550.744 m/s.
        assert!((mackenzie(25.0, 35.0, 1000.0) - 1550.744).abs() < 0.001);
    }

    #[test]
    fn saunders_pressure() {
        // Fofonoff & Millard (1983) check value: 10 000 dbar at 30° is
        // 9712.653 m; Saunders' formula is within a few dbar of it.
        let p = pressure_dbar(9712.653, 30.0);
        assert!((p - 10_000.0).abs() < 30.0, "{p}");
        assert_eq!(pressure_dbar(0.0, 45.0), 0.0);
    }

    #[test]
    fn a_nan_sample_names_its_field() {
        let s = CtdSample {
            time: 0.0,
            depth: 5.0,
            temperature: f64::NAN,
            salinity: 38.0,
        };
        let e = s.validate().unwrap_err().to_string();
        assert!(e.starts_with("sample.temperature"), "{e}");
        let s = CtdSample {
            depth: -1.0,
            temperature: 20.0,
            ..s
        };
        assert!(s
            .validate()
            .unwrap_err()
            .to_string()
            .starts_with("sample.depth"));
    }
}
