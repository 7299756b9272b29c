//! Trajectory files: CSV with the columns `t, x, y, z` (seconds, metres),
//! an optional header line, `#` comments.

use std::fmt::Write as _;

use crate::error::PositionError;
use crate::sample_coder::Sample;

/// Parses a trajectory; errors name the line.
pub fn parse_csv(text: &str) -> Result<Vec<Sample>, PositionError> {
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if out.is_empty() && fields.first().is_some_and(|f| f.eq_ignore_ascii_case("t")) {
            if fields.len() != 4
                || !fields
                    .iter()
                    .zip(["t", "x", "y", "z"])
                    .all(|(a, b)| a.eq_ignore_ascii_case(b))
            {
                return Err(PositionError::Trajectory(format!(
                    "line {}: header must be `t,x,y,z`, got `{line}`",
                    n + 1
                )));
            }
            continue;
        }
        if fields.len() != 4 {
            return Err(PositionError::Trajectory(format!(
                "line {}: expected 4 columns (t,x,y,z), got {}",
                n + 1,
                fields.len()
            )));
        }
        let mut v = [0.0; 4];
        for (i, (f, name)) in fields.iter().zip(["t", "x", "y", "z"]).enumerate() {
            v[i] = f
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    PositionError::Trajectory(format!(
                        "line {}: column {name}: `{f}` is not a finite number",
                        n + 1
                    ))
                })?;
        }
        if let Some(last) = out.last() {
            let last: &Sample = last;
            if v[0] <= last.t {
                return Err(PositionError::Trajectory(format!(
                    "line {}: time {} does not follow {}",
                    n + 1,
                    v[0],
                    last.t
                )));
            }
        }
        out.push(Sample {
            t: v[0],
            position: [v[1], v[2], v[3]],
        });
    }
    if out.is_empty() {
        return Err(PositionError::Trajectory("no samples".into()));
    }
    Ok(out)
}

/// Writes a trajectory with a `t,x,y,z` header, positions to the centimetre.
pub fn to_csv(samples: &[Sample]) -> String {
    let mut s = String::from("t,x,y,z\n");
    for p in samples {
        let _ = writeln!(
            s,
            "{},{:.2},{:.2},{:.2}",
            p.t, p.position[0], p.position[1], p.position[2]
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_reports_bad_lines() {
        let samples = vec![
            Sample {
                t: 0.0,
                position: [1.0, 2.5, -3.25],
            },
            Sample {
                t: 10.0,
                position: [4.0, 5.0, -6.0],
            },
        ];
        assert_eq!(parse_csv(&to_csv(&samples)).unwrap(), samples);
        let err = parse_csv("t,x,y,z\n0,1,2,3\n10,1,x,3\n").unwrap_err();
        assert!(err.to_string().contains("line 3: column y"), "{err}");
        let err = parse_csv("0,1,2,3\n0,1,2,3\n").unwrap_err();
        assert!(err.to_string().contains("line 2"), "{err}");
        assert!(parse_csv("").is_err());
    }
}
