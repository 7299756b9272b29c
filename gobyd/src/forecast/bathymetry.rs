//! Soundings (`forecast.bathymetry_file`): a text file of `x y depth`
//! lines, metres in the local frame, read without panics (an error names
//! the file and line), and sampled along a link as the bottom under it.

use std::path::Path;

/// The soundings of one file.
#[derive(Debug, Clone, PartialEq)]
pub struct Soundings {
    points: Vec<[f64; 3]>,
}

impl Soundings {
    /// Reads `path`. Each line holds x, y and depth (blanks or commas
    /// between); `#` starts a comment; blank lines are skipped. The error
    /// is `FILE:LINE: why`.
    pub fn read(path: &Path) -> Result<Soundings, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        Soundings::parse(&path.display().to_string(), &text)
    }

    /// Parses `text`, named `name` in errors.
    pub fn parse(name: &str, text: &str) -> Result<Soundings, String> {
        let mut points = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("");
            let words: Vec<&str> = line
                .split(|c: char| c == ',' || c.is_whitespace())
                .filter(|w| !w.is_empty())
                .collect();
            if words.is_empty() {
                continue;
            }
            let at = |why: String| format!("{name}:{}: {why}", i + 1);
            if words.len() != 3 {
                return Err(at(format!(
                    "expected \"x y depth\" (three numbers), found {} values",
                    words.len()
                )));
            }
            let mut p = [0.0; 3];
            for (k, (w, what)) in words.iter().zip(["x", "y", "depth"]).enumerate() {
                p[k] = w
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| at(format!("{what} {w:?} is not a number")))?;
            }
            if p[2] <= 0.0 {
                return Err(at(format!("depth {} m is not below the surface", p[2])));
            }
            points.push(p);
        }
        if points.is_empty() {
            return Err(format!("{name}: no soundings (\"x y depth\" lines)"));
        }
        Ok(Soundings { points })
    }

    /// The deepest sounding (m).
    pub fn deepest(&self) -> f64 {
        self.points.iter().map(|p| p[2]).fold(0.0, f64::max)
    }

    /// Depth (m) of the sounding nearest to `(x, y)`.
    pub fn depth_at(&self, x: f64, y: f64) -> f64 {
        self.points
            .iter()
            .min_by(|a, b| {
                let da = (a[0] - x).hypot(a[1] - y);
                let db = (b[0] - x).hypot(b[1] - y);
                da.total_cmp(&db)
            })
            .map_or(0.0, |p| p[2])
    }

    /// The bottom under the line from `from` to `to` (x, y in m), every
    /// `step` m: `(range m, depth m)` from 0 to the link's range (at least
    /// two points).
    pub fn along(&self, from: (f64, f64), to: (f64, f64), step: f64) -> Vec<(f64, f64)> {
        let range = (to.0 - from.0).hypot(to.1 - from.1);
        let n = ((range / step.max(1.0)).ceil() as usize).clamp(1, 10_000);
        (0..=n)
            .map(|i| {
                let f = i as f64 / n as f64;
                let x = from.0 + f * (to.0 - from.0);
                let y = from.1 + f * (to.1 - from.1);
                (f * range.max(1.0), self.depth_at(x, y))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_line_is_named_by_file_and_line() {
        let err = Soundings::parse("bay.xyz", "# x y depth\n0 0 100\n10, 0, 1o5\n").unwrap_err();
        assert_eq!(err, "bay.xyz:3: depth \"1o5\" is not a number");
        let err = Soundings::parse("bay.xyz", "0 0\n").unwrap_err();
        assert!(
            err.starts_with("bay.xyz:1: expected \"x y depth\""),
            "{err}"
        );
        let err = Soundings::parse("bay.xyz", "0 0 -5\n").unwrap_err();
        assert!(err.starts_with("bay.xyz:1: depth -5 m"), "{err}");
        assert!(Soundings::parse("bay.xyz", "# none\n").is_err());
    }

    #[test]
    fn the_bottom_along_a_link_takes_the_nearest_soundings() {
        let s = Soundings::parse("s", "0 0 100\n1000 0 50\n").unwrap();
        let b = s.along((0.0, 0.0), (1000.0, 0.0), 250.0);
        assert_eq!(b.len(), 5);
        assert_eq!(b[0], (0.0, 100.0));
        assert_eq!(b[4], (1000.0, 50.0));
    }
}
