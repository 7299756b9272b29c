//! Values the codec changes while encoding in libdccl's default (non-strict)
//! mode: an out-of-range number sent as "not present", NaN sent as the
//! minimum, a string or array truncated, an undefined enum value dropped.
//! [`Codec::encode_with`](crate::Codec::encode_with) with [`EncodeOptions::changes`](crate::EncodeOptions::changes) and
//! [`Codec::check`](crate::Codec::check) report them; in strict mode each is
//! an error instead.

use std::cell::RefCell;

/// One value changed by encoding in libdccl's default (non-strict) mode.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ValueChange {
    /// Full name of the top message (e.g. `goby.example.Command`).
    pub message: String,
    /// Path of the field from the top message: `waypoint.x`, `samples[3]`, `note`.
    pub field: String,
    /// What was changed and how, e.g. `99 is out of range [0, 31]: sent as not present`.
    pub reason: String,
}

impl std::fmt::Display for ValueChange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "message {}, field {}: {}",
            self.message, self.field, self.reason
        )
    }
}

/// Collects the changes of one encoding as (field path, reason) pairs. Codecs
/// record a change with an empty path; each enclosing message (or repeated
/// field) prefixes the path of the changes recorded while it encoded a field.
#[derive(Debug, Default)]
pub struct ChangeLog {
    entries: RefCell<Vec<(String, String)>>,
}

impl ChangeLog {
    /// An empty log.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of changes recorded so far (a mark for [`ChangeLog::prefix_since`]).
    pub fn len(&self) -> usize {
        self.entries.borrow().len()
    }

    /// Records a change of the value being encoded (path filled in by the callers).
    pub fn record(&self, reason: String) {
        self.entries.borrow_mut().push((String::new(), reason));
    }

    /// Prefixes the path of every change recorded after `mark` with
    /// `segment`: a field name (`x`, joined with a dot) or an element index (`[3]`).
    pub fn prefix_since(&self, mark: usize, segment: &str) {
        for (path, _) in self.entries.borrow_mut().iter_mut().skip(mark) {
            *path = if path.is_empty() {
                segment.to_string()
            } else if path.starts_with('[') {
                format!("{segment}{path}")
            } else {
                format!("{segment}.{path}")
            };
        }
    }

    /// The changes, each under the name of the top message.
    pub fn into_changes(self, message: &str) -> Vec<ValueChange> {
        self.entries
            .into_inner()
            .into_iter()
            .map(|(field, reason)| ValueChange {
                message: message.to_string(),
                field,
                reason,
            })
            .collect()
    }
}
