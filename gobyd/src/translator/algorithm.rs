//! The translator's algorithms: each turns the text of one field (the
//! primary field) and optionally the texts of reference fields into a new
//! text. The names and results are Goby's (its `MOOSTranslator`); numbers
//! come out with 15 significant digits.
//!
//! | name | result |
//! |---|---|
//! | `to_upper`, `to_lower` | the text in upper or lower case |
//! | `abs` | the absolute value |
//! | `add`, `subtract` | the value plus / minus every reference value |
//! | `angle_0_360`, `angle_-180_180` | the angle (degrees) wrapped into [0, 360) or [-180, 180) |
//! | `power_to_dB`, `dB_to_power` | 10·log10(v), 10^(v/10) |
//! | `lat2hemisphere_initial`, `lon2hemisphere_initial` | `N`/`S`, `E`/`W` |
//! | `lat2nmea_lat`, `lon2nmea_lon` | `DDMM.MMMM`, `DDDMM.MMMM` of the absolute value |
//! | `unix_time2nmea_time` | `HHMMSS.SSSSSS` (UTC) of seconds since the UNIX epoch |
//! | `lat2utm_y`, `lon2utm_x` | local grid y (reference: longitude), x (reference: latitude) |
//! | `utm_y2lat`, `utm_x2lon` | latitude (reference: x), longitude (reference: y) of a grid position |
//! | `modem_id2name`, `modem_id2type` | name, type of a modem id in the lookup file |
//! | `name2modem_id` | modem id of a name in the lookup file |
//!
//! Differences from Goby: `lat2nmea_lat` and `lon2nmea_lon` write the
//! absolute value (the hemisphere comes from `*2hemisphere_initial`), where
//! Goby writes a negative angle's floor; a value that is not a number is an
//! error instead of NaN.

use super::field_text::format_double;
use super::local_grid::LocalGrid;
use super::modem_id::ModemIdLookup;

/// Every algorithm name known.
pub const NAMES: &[&str] = &[
    "to_upper",
    "to_lower",
    "abs",
    "add",
    "subtract",
    "angle_0_360",
    "angle_-180_180",
    "power_to_dB",
    "dB_to_power",
    "lat2hemisphere_initial",
    "lon2hemisphere_initial",
    "lat2nmea_lat",
    "lon2nmea_lon",
    "unix_time2nmea_time",
    "lat2utm_y",
    "lon2utm_x",
    "utm_x2lon",
    "utm_y2lat",
    "modem_id2name",
    "modem_id2type",
    "name2modem_id",
];

/// The algorithms with what some of them need: the local grid and the
/// modem-id lookup.
#[derive(Debug, Default)]
pub struct Algorithms {
    grid: Option<LocalGrid>,
    ids: Option<ModemIdLookup>,
}

fn number(name: &str, text: &str) -> Result<f64, String> {
    text.trim()
        .parse::<f64>()
        .map_err(|_| format!("{name}: {text:?} is not a number"))
}

/// Rounds `v` to `decimals` decimal places.
fn round_to(v: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (v * scale).round() / scale
}

/// `DDMM.MMMM` of an angle (with `degree_digits` digits of degrees).
fn nmea_angle(v: f64, degree_digits: usize) -> String {
    let v = v.abs();
    let degrees = v.floor();
    let minutes_total = (v - degrees) * 60.0;
    let minutes = minutes_total.floor();
    let ten_thousandths = ((minutes_total - minutes) * 10000.0).floor();
    format!(
        "{:0w$}{:02}.{:04}",
        degrees as i64,
        minutes as i64,
        ten_thousandths as i64,
        w = degree_digits
    )
}

impl Algorithms {
    /// The algorithms without a local grid or a lookup file.
    pub fn new() -> Self {
        Self::default()
    }

    /// With the local grid (for the `utm` algorithms).
    pub fn with_local_grid(mut self, grid: LocalGrid) -> Self {
        self.grid = Some(grid);
        self
    }

    /// With the modem-id lookup (for `modem_id2name`, `modem_id2type`,
    /// `name2modem_id`).
    pub fn with_modem_ids(mut self, ids: ModemIdLookup) -> Self {
        self.ids = Some(ids);
        self
    }

    /// Whether `name` is an algorithm.
    pub fn is_known(name: &str) -> bool {
        NAMES.contains(&name)
    }

    fn grid(&self, name: &str) -> Result<&LocalGrid, String> {
        self.grid.as_ref().ok_or_else(|| {
            format!("{name} needs the local grid's origin (LatOrigin and LongOrigin)")
        })
    }

    fn ids(&self, name: &str) -> Result<&ModemIdLookup, String> {
        self.ids
            .as_ref()
            .ok_or_else(|| format!("{name} needs a modem id lookup file (modem_id_lookup_path)"))
    }

    /// Runs algorithm `name` on `value` with the reference values `refs`.
    pub fn run(&self, name: &str, value: &str, refs: &[String]) -> Result<String, String> {
        let num = || number(name, value);
        let reference = |i: usize| -> Result<f64, String> {
            let text = refs
                .get(i)
                .ok_or_else(|| format!("{name} needs {} reference field(s)", i + 1))?;
            number(name, text)
        };
        let is_id = !value.is_empty() && value.bytes().all(|b| b.is_ascii_digit());
        Ok(match name {
            "to_upper" => value.to_uppercase(),
            "to_lower" => value.to_lowercase(),
            "abs" => format_double(num()?.abs()),
            "add" => {
                let mut v = num()?;
                for i in 0..refs.len() {
                    v += reference(i)?;
                }
                format_double(v)
            }
            "subtract" => {
                let mut v = num()?;
                for i in 0..refs.len() {
                    v -= reference(i)?;
                }
                format_double(v)
            }
            "angle_0_360" => {
                let a = num()?.rem_euclid(360.0);
                format_double(if a >= 360.0 { 0.0 } else { a })
            }
            "angle_-180_180" => {
                let a = (num()? + 180.0).rem_euclid(360.0) - 180.0;
                format_double(if a >= 180.0 { -180.0 } else { a })
            }
            "power_to_dB" => format_double(10.0 * num()?.log10()),
            "dB_to_power" => format_double(10f64.powf(num()? / 10.0)),
            "lat2hemisphere_initial" => if num()? < 0.0 { "S" } else { "N" }.into(),
            "lon2hemisphere_initial" => if num()? < 0.0 { "W" } else { "E" }.into(),
            "lat2nmea_lat" => nmea_angle(num()?, 2),
            "lon2nmea_lon" => nmea_angle(num()?, 3),
            "unix_time2nmea_time" => {
                let t = num()?;
                let micros = (t * 1e6).round() as i64;
                let of_day = micros.rem_euclid(86_400_000_000);
                let secs = of_day / 1_000_000;
                format!(
                    "{:02}{:02}{:02}.{:06}",
                    secs / 3600,
                    secs / 60 % 60,
                    secs % 60,
                    of_day % 1_000_000
                )
            }
            "lat2utm_y" => {
                let (_, y) = self.grid(name)?.to_local(num()?, reference(0)?)?;
                format_double(y)
            }
            "lon2utm_x" => {
                let (x, _) = self.grid(name)?.to_local(reference(0)?, num()?)?;
                format_double(x)
            }
            "utm_x2lon" => {
                let (_, lon) = self.grid(name)?.to_geo(num()?, reference(0)?)?;
                format_double(round_to(lon, 11))
            }
            "utm_y2lat" => {
                let (lat, _) = self.grid(name)?.to_geo(reference(0)?, num()?)?;
                format_double(round_to(lat, 12))
            }
            "modem_id2name" => {
                let ids = self.ids(name)?;
                match value.parse::<i32>() {
                    Ok(id) if is_id => ids.name(id),
                    _ => value.to_string(),
                }
            }
            "modem_id2type" => {
                let ids = self.ids(name)?;
                match value.parse::<i32>() {
                    Ok(id) if is_id => ids.vehicle_type(id),
                    _ => value.to_string(),
                }
            }
            "name2modem_id" => match self.ids(name)?.id(value) {
                Some(id) => id.to_string(),
                None => {
                    return Err(format!(
                        "{name}: {value:?} is not a name in the lookup file nor a number"
                    ))
                }
            },
            other => {
                return Err(format!(
                    "unknown algorithm {other:?} (known: {})",
                    NAMES.join(", ")
                ))
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(a: &Algorithms, name: &str, v: &str, refs: &[&str]) -> String {
        let refs: Vec<String> = refs.iter().map(|s| s.to_string()).collect();
        a.run(name, v, &refs).unwrap()
    }

    #[test]
    fn each_algorithm_gives_gobys_result() {
        let ids = ModemIdLookup::parse("1, resolution, ship\n3, unicorn, auv\n").unwrap();
        let a = Algorithms::new()
            .with_local_grid(LocalGrid::new(42.5, 10.8).unwrap())
            .with_modem_ids(ids);
        for (name, v, refs, out) in [
            ("to_upper", "Unicorn", &[][..], "UNICORN"),
            ("to_lower", "UNICORN", &[], "unicorn"),
            ("abs", "-3.25", &[], "3.25"),
            ("add", "550", &["1023.5"], "1573.5"),
            ("subtract", "550", &["1023.5"], "-473.5"),
            ("angle_0_360", "-120", &[], "240"),
            ("angle_0_360", "720", &[], "0"),
            ("angle_-180_180", "270", &[], "-90"),
            ("angle_-180_180", "180", &[], "-180"),
            ("power_to_dB", "100", &[], "20"),
            ("dB_to_power", "30", &[], "1000"),
            ("lat2hemisphere_initial", "-42.5", &[], "S"),
            ("lat2hemisphere_initial", "42.5", &[], "N"),
            ("lon2hemisphere_initial", "-70.1", &[], "W"),
            ("lon2hemisphere_initial", "10.8", &[], "E"),
            ("lat2nmea_lat", "42.5", &[], "4230.0000"),
            ("lat2nmea_lat", "-42.25", &[], "4215.0000"),
            ("lon2nmea_lon", "10.8", &[], "01048.0000"),
            ("unix_time2nmea_time", "1700000000.5", &[], "221320.500000"),
            ("modem_id2name", "3", &[], "unicorn"),
            ("modem_id2name", "9", &[], "9"),
            ("modem_id2name", "x3", &[], "x3"),
            ("modem_id2type", "1", &[], "ship"),
            ("modem_id2type", "9", &[], "unknown_type"),
            ("name2modem_id", "Unicorn", &[], "3"),
            ("name2modem_id", "12", &[], "12"),
        ] {
            assert_eq!(run(&a, name, v, refs), out, "{name}({v})");
        }
        // The grid both ways: a position and back.
        let lat = run(&a, "utm_y2lat", "1023.5", &["550"]);
        let lon = run(&a, "utm_x2lon", "550", &["1023.5"]);
        let y: f64 = run(&a, "lat2utm_y", &lat, &[&lon]).parse().unwrap();
        let x: f64 = run(&a, "lon2utm_x", &lon, &[&lat]).parse().unwrap();
        assert!(
            (x - 550.0).abs() < 1e-4 && (y - 1023.5).abs() < 1e-4,
            "{x} {y}"
        );
        assert!(
            lat.starts_with("42.509") && lon.starts_with("10.806"),
            "{lat} {lon}"
        );
    }

    #[test]
    fn bad_values_and_missing_setup_are_errors() {
        let a = Algorithms::new();
        for (name, v, refs, expected) in [
            ("abs", "abc", &[][..], "not a number"),
            ("add", "1", &["x"], "not a number"),
            ("lat2utm_y", "42", &["10"], "LatOrigin"),
            ("modem_id2name", "3", &[], "modem_id_lookup_path"),
            ("frobnicate", "3", &[], "unknown algorithm"),
        ] {
            let refs: Vec<String> = refs.iter().map(|s| s.to_string()).collect();
            let err = a.run(name, v, &refs).unwrap_err();
            assert!(err.contains(expected), "{name}: {err}");
        }
        let a = Algorithms::new().with_local_grid(LocalGrid::new(42.5, 10.8).unwrap());
        let err = a.run("utm_x2lon", "5", &[]).unwrap_err();
        assert!(err.contains("reference"), "{err}");
    }
}
