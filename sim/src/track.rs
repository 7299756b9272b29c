//! Where each node is during a run: fixed, or moving along its track
//! (waypoints joined by straight legs run at a constant speed, depth
//! changing evenly along each leg; held at the last waypoint, or around
//! again from the first with `repeat`).

use std::time::Duration;

use modemdriver::sim::positions::Positions;
use modemdriver::sim::reception::Position;

/// A node's place over the run: `[x, y, depth]` in metres (x east, y
/// north, depth down).
#[derive(Debug, Clone, PartialEq)]
pub enum Place {
    /// Where it stays.
    Fixed([f64; 3]),
    /// Where it goes.
    Track(Track),
}

impl Place {
    /// Where it is `elapsed` after the run's start.
    pub fn at(&self, elapsed: Duration) -> [f64; 3] {
        match self {
            Place::Fixed(p) => *p,
            Place::Track(t) => t.at(elapsed.as_secs_f64()),
        }
    }

    /// Where it starts.
    pub fn start(&self) -> [f64; 3] {
        self.at(Duration::ZERO)
    }
}

/// Waypoints run through in order at `speed` (m/s, > 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    /// At least one; the node starts at the first.
    pub waypoints: Vec<[f64; 3]>,
    /// Metres per second along each leg (the depth change included).
    pub speed: f64,
    /// After the last waypoint, on to the first and around again.
    pub repeat: bool,
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

impl Track {
    /// The legs as (from, to, metres), the closing leg included with
    /// `repeat`.
    fn legs(&self) -> impl Iterator<Item = (&[f64; 3], &[f64; 3], f64)> {
        let closing = self
            .repeat
            .then(|| (self.waypoints.last(), self.waypoints.first()));
        self.waypoints
            .windows(2)
            .map(|w| (&w[0], &w[1]))
            .chain(closing.and_then(|(a, b)| Some((a?, b?))))
            .map(|(a, b)| (a, b, distance(a, b)))
    }

    /// The metres of one time round (to the last waypoint, or back to the
    /// first with `repeat`).
    pub fn length(&self) -> f64 {
        self.legs().map(|(_, _, d)| d).sum()
    }

    /// Where it is `seconds` after the start.
    pub fn at(&self, seconds: f64) -> [f64; 3] {
        let Some(first) = self.waypoints.first() else {
            return [0.0; 3];
        };
        let length = self.length();
        if length <= 0.0 || self.speed <= 0.0 {
            return *first;
        }
        let mut along = self.speed * seconds.max(0.0);
        if self.repeat {
            along %= length;
        } else if along >= length {
            return *self.waypoints.last().unwrap_or(first);
        }
        for (a, b, d) in self.legs() {
            if along <= d && d > 0.0 {
                let f = along / d;
                return [0, 1, 2].map(|k| a[k] + (b[k] - a[k]) * f);
            }
            along -= d;
        }
        *self.waypoints.last().unwrap_or(first)
    }
}

/// Every node's place, for the simulated modems ([`Positions`]).
#[derive(Debug)]
pub struct World {
    /// The run's start, microseconds since the UNIX epoch.
    pub start_micros: i64,
    /// (modem id, place) of each node.
    pub places: Vec<(i32, Place)>,
}

impl Positions for World {
    fn at(&self, modem_id: i32, micros: u64) -> Option<Position> {
        let (_, place) = self.places.iter().find(|(id, _)| *id == modem_id)?;
        let elapsed = (micros as i64).saturating_sub(self.start_micros).max(0);
        let [x, y, depth] = place.at(Duration::from_micros(elapsed as u64));
        Some(Position::new(x, y, -depth))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn track(repeat: bool) -> Track {
        // 300 m east, then 400 m north at 10 m depth, at 2 m/s.
        Track {
            waypoints: vec![[0.0, 0.0, 10.0], [300.0, 0.0, 10.0], [300.0, 400.0, 10.0]],
            speed: 2.0,
            repeat,
        }
    }

    #[test]
    fn a_track_is_run_leg_by_leg_at_its_speed_and_held_at_its_end() {
        let t = track(false);
        assert_eq!(t.length(), 700.0);
        assert_eq!(t.at(0.0), [0.0, 0.0, 10.0]);
        assert_eq!(t.at(75.0), [150.0, 0.0, 10.0]);
        assert_eq!(t.at(150.0), [300.0, 0.0, 10.0]);
        assert_eq!(t.at(250.0), [300.0, 200.0, 10.0]);
        assert_eq!(t.at(10_000.0), [300.0, 400.0, 10.0]);
    }

    #[test]
    fn a_repeated_track_closes_back_to_its_first_waypoint() {
        let t = track(true);
        // 700 m, then 500 m back to the start: 1200 m a round.
        assert_eq!(t.length(), 1200.0);
        assert_eq!(t.at(350.0 + 125.0), [150.0, 200.0, 10.0]);
        let round = 600.0;
        assert_eq!(t.at(round + 75.0), t.at(75.0));
    }

    #[test]
    fn depth_changes_evenly_along_a_leg() {
        let t = Track {
            waypoints: vec![[0.0, 0.0, 0.0], [0.0, 0.0, 100.0]],
            speed: 0.5,
            repeat: false,
        };
        assert_eq!(t.at(100.0), [0.0, 0.0, 50.0]);
    }

    #[test]
    fn the_world_gives_modem_positions_up_from_the_run_start() {
        let world = World {
            start_micros: 1_000_000,
            places: vec![
                (3, Place::Track(track(false))),
                (4, Place::Fixed([5.0, 6.0, 7.0])),
            ],
        };
        let p = world.at(3, 1_000_000 + 75_000_000).unwrap();
        assert_eq!((p.x, p.y, p.z), (150.0, 0.0, -10.0));
        let fixed = world.at(4, 0).unwrap();
        assert_eq!((fixed.x, fixed.y, fixed.z), (5.0, 6.0, -7.0));
        assert!(world.at(9, 0).is_none());
    }
}
