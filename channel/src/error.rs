//! Errors of the channel model: bad input names its field, a file's errors
//! name the file, line and field.

use std::fmt;

/// An error in a text file: the file, the 1-based line, the field read and
/// what was wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParseError {
    /// File name as given by the caller (e.g. `summer.env`).
    pub file: String,
    /// 1-based line number.
    pub line: usize,
    /// The field being read (e.g. `SSP point 3 depth`).
    pub field: String,
    /// What was wrong.
    pub message: String,
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}: {}: {}",
            self.file, self.line, self.field, self.message
        )
    }
}

impl std::error::Error for ParseError {}

/// An error of the channel model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChannelError {
    /// A value that cannot be used: `field` names it (e.g.
    /// `profile.points[2].depth`, `source.depth`).
    #[error("{field}: {message}")]
    Invalid {
        /// The offending field.
        field: String,
        /// Why it cannot be used.
        message: String,
    },
    /// A file that does not parse.
    #[error(transparent)]
    Parse(#[from] ParseError),
    /// The computation was cancelled by its caller.
    #[error("the computation was cancelled")]
    Cancelled,
}

impl ChannelError {
    /// A [`ChannelError::Invalid`] for `field`.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        ChannelError::Invalid {
            field: field.into(),
            message: message.into(),
        }
    }
}

/// Checks that `value` is finite, naming `field` otherwise.
pub(crate) fn finite(field: &str, value: f64) -> Result<f64, ChannelError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(ChannelError::invalid(
            field,
            format!("{value} is not a finite number"),
        ))
    }
}

/// Checks that `value` is finite and at least zero.
pub(crate) fn non_negative(field: &str, value: f64) -> Result<f64, ChannelError> {
    finite(field, value)?;
    if value < 0.0 {
        return Err(ChannelError::invalid(field, format!("{value} is negative")));
    }
    Ok(value)
}

/// Checks that `value` is finite and above zero.
pub(crate) fn positive(field: &str, value: f64) -> Result<f64, ChannelError> {
    finite(field, value)?;
    if value <= 0.0 {
        return Err(ChannelError::invalid(
            field,
            format!("{value} is not above zero"),
        ));
    }
    Ok(value)
}
