//! A link's byte budget (Iridium costs money per message): at most
//! `bytes` bytes of frames per period, the periods starting at multiples
//! of their length since the UNIX epoch (86400 s: UTC days). What each
//! link spent in the current period is kept in `DATA_DIR/link_budget`,
//! written durably (a new file synced, renamed over the old, the
//! directory synced) before the frames that spent it reach the driver, so
//! a restart, even after SIGKILL or a power loss, never spends a period's
//! bytes twice.
//!
//! The file is one JSON object:
//! `{"links": {"NAME": {"period_start": µs, "period_seconds": s, "spent": bytes}}}`.
//! A file that cannot be read is taken as the whole budget spent for the
//! current period (told in the log): spending twice costs money, waiting
//! for the next period only time.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};

/// The budget of one link: what it may spend and has spent this period.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    bytes: u64,
    period: i64,
    period_start: i64,
    spent: u64,
}

impl Budget {
    /// `bytes` per period of `period_seconds`, nothing spent, the period
    /// holding `now` (microseconds since the epoch) under way.
    pub fn new(bytes: u64, period_seconds: f64, now: i64) -> Self {
        let period = ((period_seconds * 1e6) as i64).max(1);
        Budget {
            bytes,
            period,
            period_start: now.div_euclid(period) * period,
            spent: 0,
        }
    }

    /// Starts the period holding `now` if it is a later one (nothing spent
    /// in it yet); returns whether it did.
    pub fn roll(&mut self, now: i64) -> bool {
        let start = now.div_euclid(self.period) * self.period;
        if start > self.period_start {
            self.period_start = start;
            self.spent = 0;
            return true;
        }
        false
    }

    /// Bytes left in the period holding `now`.
    pub fn left(&mut self, now: i64) -> u64 {
        self.roll(now);
        self.bytes.saturating_sub(self.spent)
    }

    /// Counts `n` bytes sent at `now`.
    pub fn spend(&mut self, n: u64, now: i64) {
        self.roll(now);
        self.spent = self.spent.saturating_add(n);
    }

    /// Takes what a previous run recorded, when it is of the current
    /// period and of a period of the same length.
    pub fn restore(&mut self, kept: &Kept) {
        if kept.period_start == self.period_start && kept.period == self.period {
            self.spent = kept.spent;
        }
    }

    /// Takes the whole budget as spent this period.
    pub fn exhaust(&mut self) {
        self.spent = self.bytes;
    }

    /// The budget, bytes per period.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Bytes spent in the current period.
    pub fn spent(&self) -> u64 {
        self.spent
    }

    /// Start of the current period, microseconds since the epoch.
    pub fn period_start(&self) -> i64 {
        self.period_start
    }

    /// The period's length, microseconds.
    pub fn period(&self) -> i64 {
        self.period
    }

    /// When the next period starts, microseconds since the epoch.
    #[cfg(test)]
    pub fn next_period(&self) -> i64 {
        self.period_start.saturating_add(self.period)
    }

    /// What the file keeps of it.
    pub fn kept(&self) -> Kept {
        Kept {
            period_start: self.period_start,
            period: self.period,
            spent: self.spent,
        }
    }
}

/// What the file keeps of one link's budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Kept {
    /// Start of the period, microseconds since the epoch.
    pub period_start: i64,
    /// Its length, microseconds.
    pub period: i64,
    /// Bytes spent in it.
    pub spent: u64,
}

/// `DATA_DIR/link_budget`.
#[derive(Debug)]
pub struct BudgetFile {
    path: PathBuf,
}

impl BudgetFile {
    /// The file in the data directory `dir`.
    pub fn in_dir(dir: &Path) -> Self {
        BudgetFile {
            path: dir.join("link_budget"),
        }
    }

    /// Where it is.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// What it keeps, by link name: empty when there is no file; an error
    /// naming the file when it cannot be read or is not one.
    pub fn load(&self) -> Result<HashMap<String, Kept>, String> {
        let text = match std::fs::read_to_string(&self.path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(HashMap::new()),
            Err(e) => return Err(format!("{}: {e}", self.path.display())),
        };
        let bad = |what: &str| format!("{}: {what}", self.path.display());
        let value: Value =
            serde_json::from_str(&text).map_err(|e| bad(&format!("not JSON: {e}")))?;
        let links = value
            .get("links")
            .and_then(Value::as_object)
            .ok_or_else(|| bad("no \"links\" object"))?;
        let mut kept = HashMap::new();
        for (name, v) in links {
            let field = |f: &str| v.get(f).and_then(Value::as_i64);
            let (Some(period_start), Some(period), Some(spent)) = (
                field("period_start"),
                v.get("period_seconds")
                    .and_then(Value::as_f64)
                    .map(|s| (s * 1e6) as i64),
                v.get("spent").and_then(Value::as_u64),
            ) else {
                return Err(bad(&format!(
                    "link {name:?}: period_start, period_seconds and spent expected"
                )));
            };
            kept.insert(
                name.clone(),
                Kept {
                    period_start,
                    period,
                    spent,
                },
            );
        }
        Ok(kept)
    }

    /// Writes what each link spent, durably: a new file synced and renamed
    /// over the old one, then the directory synced (mode 0600).
    pub fn save<'a>(
        &self,
        budgets: impl IntoIterator<Item = (&'a str, Kept)>,
    ) -> std::io::Result<()> {
        let mut links = serde_json::Map::new();
        for (name, k) in budgets {
            links.insert(
                name.to_string(),
                json!({
                    "period_start": k.period_start,
                    "period_seconds": k.period as f64 / 1e6,
                    "spent": k.spent,
                }),
            );
        }
        let text = json!({ "links": links }).to_string() + "\n";
        goby_store::file::write_atomically(&self.path, text.as_bytes())?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DAY: i64 = 86_400_000_000;

    #[test]
    fn a_budget_is_spent_within_its_period_and_rolls_over_at_the_next() {
        let t = 20_000 * DAY + 5;
        let mut b = Budget::new(100, 86_400.0, t);
        assert_eq!(b.period_start(), 20_000 * DAY);
        b.spend(60, t);
        assert_eq!(b.left(t + 1), 40);
        b.spend(60, t + 2);
        assert_eq!(b.left(t + 3), 0, "never below nothing");
        assert_eq!(b.next_period(), 20_001 * DAY);
        assert_eq!(b.left(20_001 * DAY), 100);
        assert_eq!(b.spent(), 0);
        // An earlier time (the clock stepped back) does not roll back.
        assert!(!b.roll(t));
    }

    #[test]
    fn what_was_spent_survives_in_the_file_for_its_period_only() {
        let dir = std::env::temp_dir().join(format!("gobyd-budget-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let file = BudgetFile::in_dir(&dir);
        assert!(file.load().unwrap().is_empty());
        let t = 20_000 * DAY + 5;
        let mut b = Budget::new(100, 86_400.0, t);
        b.spend(70, t);
        file.save([("iridium", b.kept())]).unwrap();
        let kept = file.load().unwrap();
        let mut again = Budget::new(100, 86_400.0, t + 1000);
        again.restore(&kept["iridium"]);
        assert_eq!(again.spent(), 70);
        // The next day starts afresh; another period length too.
        let mut tomorrow = Budget::new(100, 86_400.0, t + DAY);
        tomorrow.restore(&kept["iridium"]);
        assert_eq!(tomorrow.spent(), 0);
        let mut hourly = Budget::new(100, 3_600.0, t);
        hourly.restore(&kept["iridium"]);
        assert_eq!(hourly.spent(), 0);
        std::fs::write(file.path(), "{ torn").unwrap();
        let err = file.load().unwrap_err();
        assert!(err.contains("link_budget: not JSON"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
