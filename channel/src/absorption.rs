//! Absorption of sound in sea water, and the complex sound speed BELLHOP
//! builds from a speed and an attenuation.
//!
//! Sources: W. H. Thorp, "Analytic description of the low-frequency
//! attenuation coefficient", JASA 42 (1967) 270, in the form with the
//! low-frequency term used by the Acoustics Toolbox; R. E. Francois and
//! G. R. Garrison, "Sound absorption based on ocean measurements", JASA 72
//! (1982) 896 and 1879 (boric acid, magnesium sulphate and pure water
//! terms), in the simplified form of the Acoustics Toolbox.

use num_complex::Complex64;

use crate::environment::{AttenuationUnit, VolumeAttenuation};

/// dB per neper (20 log10 e).
const DB_PER_NEPER: f64 = 8.685_889_6;

/// Thorp's absorption (dB/km) at `frequency` (Hz).
///
/// `α = 0.0033 + 0.11 f²/(1+f²) + 44 f²/(4100+f²) + 0.0003 f²`, f in kHz:
/// about 1 dB/km at 10 kHz, 6 dB/km at 25 kHz.
pub fn thorp_db_per_km(frequency: f64) -> f64 {
    let f2 = (frequency / 1000.0).powi(2);
    3.3e-3 + 0.11 * f2 / (1.0 + f2) + 44.0 * f2 / (4100.0 + f2) + 3e-4 * f2
}

/// Francois–Garrison absorption (dB/km) at `frequency` (Hz) in water of
/// `temperature` (°C), `salinity` (psu), `ph` and `depth` (m).
pub fn francois_garrison_db_per_km(
    frequency: f64,
    temperature: f64,
    salinity: f64,
    ph: f64,
    depth: f64,
) -> f64 {
    let f = frequency / 1000.0;
    let t = temperature;
    let s = salinity;
    let z = depth;
    let c = 1412.0 + 3.21 * t + 1.19 * s + 0.0167 * z;
    // Boric acid.
    let a1 = 8.86 / c * 10f64.powf(0.78 * ph - 5.0);
    let f1 = 2.8 * (s / 35.0).sqrt() * 10f64.powf(4.0 - 1245.0 / (t + 273.0));
    // Magnesium sulphate.
    let a2 = 21.44 * s / c * (1.0 + 0.025 * t);
    let p2 = 1.0 - 1.37e-4 * z + 6.2e-9 * z * z;
    let f2 = 8.17 * 10f64.powf(8.0 - 1990.0 / (t + 273.0)) / (1.0 + 0.0018 * (s - 35.0));
    // Pure water.
    let p3 = 1.0 - 3.83e-5 * z + 4.9e-10 * z * z;
    let a3 = if t < 20.0 {
        4.937e-4 - 2.59e-5 * t + 9.11e-7 * t * t - 1.5e-8 * t * t * t
    } else {
        3.964e-4 - 1.146e-5 * t + 1.45e-7 * t * t - 6.5e-10 * t * t * t
    };
    a1 * f1 * f * f / (f1 * f1 + f * f) + a2 * p2 * f2 * f * f / (f2 * f2 + f * f) + a3 * p3 * f * f
}

/// Volume absorption (dB/km) of `volume` at `frequency` (Hz); 0 for
/// [`VolumeAttenuation::None`].
pub fn volume_db_per_km(volume: &VolumeAttenuation, frequency: f64) -> f64 {
    match *volume {
        VolumeAttenuation::None => 0.0,
        VolumeAttenuation::Thorp => thorp_db_per_km(frequency),
        VolumeAttenuation::FrancoisGarrison {
            temperature,
            salinity,
            ph,
            depth,
        } => francois_garrison_db_per_km(frequency, temperature, salinity, ph, depth),
    }
}

/// The complex sound speed `c + i c_i` for speed `c` (m/s) and attenuation
/// `alpha` in `unit`, plus `volume`, at `frequency` (Hz): the imaginary
/// part is α c²/ω with α in nepers/m.
pub(crate) fn complex_speed(
    c: f64,
    alpha: f64,
    frequency: f64,
    unit: AttenuationUnit,
    volume: &VolumeAttenuation,
) -> Complex64 {
    let omega = 2.0 * std::f64::consts::PI * frequency;
    let mut a = match unit {
        AttenuationUnit::NepersPerMetre => alpha,
        AttenuationUnit::DbPerMetre => alpha / DB_PER_NEPER,
        AttenuationUnit::DbPerMetreKhz => alpha * frequency / (1000.0 * DB_PER_NEPER),
        AttenuationUnit::DbPerWavelength if c != 0.0 => alpha * frequency / (DB_PER_NEPER * c),
        AttenuationUnit::Q if c * alpha != 0.0 => omega / (2.0 * c * alpha),
        AttenuationUnit::LossParameter if c != 0.0 => alpha * omega / c,
        _ => 0.0,
    };
    a += volume_db_per_km(volume, frequency) / (1000.0 * DB_PER_NEPER);
    Complex64::new(c, a * c * c / omega)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thorp_at_known_frequencies() {
        // About 1.2 dB/km at 10 kHz, 6.1 at 25 kHz.
        assert!((thorp_db_per_km(10_000.0) - 1.19).abs() < 0.05);
        assert!((thorp_db_per_km(25_000.0) - 6.12).abs() < 0.05);
    }

    #[test]
    fn francois_garrison_at_a_known_point() {
        // 10 kHz, 4 °C, 35 psu, pH 8, 1000 m: about 1 dB/km (Francois &
        // Garrison 1982, Fig. 6).
        let a = francois_garrison_db_per_km(10_000.0, 4.0, 35.0, 8.0, 1000.0);
        assert!((0.8..1.2).contains(&a), "{a}");
        // 25 kHz, 20 °C, shallow: a few dB/km.
        let a = francois_garrison_db_per_km(25_000.0, 20.0, 38.0, 8.1, 50.0);
        assert!((3.0..8.0).contains(&a), "{a}");
    }

    #[test]
    fn db_per_wavelength_to_imaginary_speed() {
        let c = complex_speed(
            1600.0,
            0.5,
            100.0,
            AttenuationUnit::DbPerWavelength,
            &VolumeAttenuation::None,
        );
        // α = 0.5 f / (8.686 c) Np/m; ci = α c² / ω.
        let alpha = 0.5 * 100.0 / (DB_PER_NEPER * 1600.0);
        let want = alpha * 1600.0 * 1600.0 / (2.0 * std::f64::consts::PI * 100.0);
        assert!((c.im - want).abs() < 1e-12);
        assert_eq!(c.re, 1600.0);
    }
}
